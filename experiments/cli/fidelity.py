"""``sgatwalk fidelity``: how well does each training world rank and score gaits against real trials?

For a panel of gaits (θ0, N gaits drawn in the optimizer's trust region around θ0, and any θ files
given), runs M paired real trials per gait and evaluates every training world on the same gaits:
the plain sim, the action-noise envelope, GAT and SGAT fitted exactly as ``sgatwalk optimize``'s
first grounding step fits them, the sim with the physics ``sgatwalk diagnose`` identified, and SGAT
on top of that (hybrid). Worlds that learn from real data are fitted K times on independent draws
of it. Prints per world, over the K draws: Spearman ρ with the real fitness (with a 90 % bootstrap
interval), the mean absolute error and bias of the fitness, the Brier score of the fall frequency,
the regret of the world's pick and the ceiling the real trials' noise allows; paired tests of the
rankings (ρ(world) − ρ(reference) with 90 % intervals and p-values, on this panel and for a new one);
for every grounded world, how often the sim falls where the real robot fell when it is teacher-forced
along its own grounding walks; and fidelity against the number of episodes per gait.

Worlds are written as everywhere in sgatwalk (docs/concepts/worlds.md), options after ':', e.g.
``--worlds sim sgat sgat:ensemble=1 hybrid:delay=auto real``. ``real`` (not a default: it costs real
trials) is the real world itself on fresh seeds: what a world that is exactly right gets with as
many episodes per gait; ``real:mean=1`` its mean physics, one point.

Writes fidelity.json, fidelity.png (predicted vs real fitness, one colour per draw),
fidelity_episodes.png and table.txt into the run directory. Re-running the same command resumes
where it stopped; with more worlds or another --episodes it measures only what is new.
"""

from __future__ import annotations

import argparse
import os

import experiments.cli.argtypes as A


def register(sub) -> argparse.ArgumentParser:
    from experiments.fidelity.config import DEFAULT_WORLDS, FidelityConfig  # imports no engine

    p = sub.add_parser("fidelity", help="how well each training world predicts real gait fitness",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    d = FidelityConfig()
    p.add_argument("--worlds", type=A.world, nargs="+", default=None, metavar="WORLD",
                   help=f"training worlds (default: {' '.join(DEFAULT_WORLDS)}; robots other than the NAO: without "
                        "identified and hybrid)")
    p.add_argument("--gaits", type=A.count(0, 1000), default=d.gaits, help=f"gaits drawn around θ0 besides θ0 (default {d.gaits})")
    p.add_argument("--box", type=A.real(0.0, 1.0, open_lo=True), default=d.box,
                   help=f"half-width of the box the gaits are drawn in, normalized (default {d.box}: optimize's trust region)")
    p.add_argument("--params", type=A.in_file, nargs="+", default=[], metavar="THETA_JSON",
                   help="more gaits: θ files (e.g. a run's thetas/*.json); every world is then also scored on the drawn "
                        "and the given gaits apart")
    p.add_argument("--real-trials", type=A.count(2, 10000), default=d.real_trials,
                   help=f"paired real trials per gait (default {d.real_trials})")
    p.add_argument("--data-seeds", type=A.count(1, 100), default=d.data_seeds,
                   help=f"independent draws of the real data each learned world is fitted on (default {d.data_seeds})")
    p.add_argument("--episodes", type=A.count(1, 1000), default=d.episodes,
                   help=f"episodes per gait in a stochastic training world (default {d.episodes})")
    p.add_argument("--seconds", type=A.seconds, default=d.seconds, help=f"episode length [s] (default {d.seconds})")
    A.add_profile(p)
    p.add_argument("--identify-budget", type=A.real(0.0, 86400.0, unit="s"), default=d.identify_budget_s, metavar="SECONDS",
                   help=f"wall-clock budget of each diagnosis of the identified worlds, a safety net (default "
                        f"{d.identify_budget_s:g}; a budget that binds makes them depend on the machine's speed)")
    p.add_argument("--seed", type=A.seed, default=d.seed, help="seed of the panel, trials and data draws (default 0)")
    p.add_argument("--out", type=A.out_dir, help="run directory (default runs/fidelity-seed<seed>)")
    A.add_executor(p)
    A.add_robot(p)
    return p


def run(args) -> dict:
    from experiments.fidelity.config import DEFAULT_WORLDS, FidelityConfig
    from experiments.fidelity.report import format_phases, format_table
    from experiments.fidelity.run import Fidelity  # lazy: loads the engines and torch
    from experiments.runtime.executors import make_executor
    from experiments.runtime.progress import Reporter
    from experiments.runtime.rundir import check_run_dir

    worlds = args.worlds
    if worlds is None:  # the identified worlds are the NAO's (sgatwalk diagnose identifies the NAO)
        worlds = [w for w in DEFAULT_WORLDS if args.robot == "nao" or w not in ("identified", "hybrid")]
    with A.user_input():
        cfg = FidelityConfig(worlds=tuple(worlds), gaits=args.gaits, box=args.box, params=tuple(args.params),
                             real_trials=args.real_trials, data_seeds=args.data_seeds, episodes=args.episodes,
                             seconds=args.seconds, profile=args.profile or "real", stochasticity=args.stochasticity,
                             identify_budget_s=args.identify_budget,
                             seed=args.seed, robot=args.robot)
        cfg.validate()
        for p in cfg.params:  # every θ file readable as the robot's gait
            cfg.params_class.load(p)
        out = args.out or os.path.join("runs", f"fidelity-{'' if args.robot == 'nao' else args.robot + '-'}seed{args.seed}")
        check_run_dir(out, cfg.to_dict(), "fidelity run", ignore=cfg.RESUMABLE)
    with make_executor(args.workers, args.ray_address) as ex:
        res = Fidelity(cfg, out, ex, reporter=Reporter("fidelity")).run()
    res["run_dir"] = out  # res["wall_s"]: the run's time over all its invocations (timing.json)
    if not args.json:
        print(format_table(res), flush=True)
        figs = "fidelity.png" + (", fidelity_episodes.png" if os.path.exists(os.path.join(out, "fidelity_episodes.png")) else "")
        print(f"run directory: {out} (fidelity.json, {figs}, table.txt)", flush=True)
        print(f"time: {res['wall_s'] / 60:.1f} min over the run's invocations ({format_phases(res['phases_s'])})",
              flush=True)
    return res
