"""``sgatwalk fidelity``: how well does each training world rank and score gaits against real trials?

For a panel of gaits (θ0, N gaits drawn in the optimizer's trust region around θ0, and any θ files
given), runs M paired real trials per gait and evaluates every training world on the same gaits:
the plain sim, the action-noise envelope, GAT and SGAT grounded sims fitted exactly as
``sgatwalk optimize``'s first grounding step fits them, the sim with the physics ``sgatwalk
diagnose`` identified, and SGAT on top of that (hybrid). Worlds that learn from real data are fitted
K times on independent draws of it. Prints per world the Spearman ρ with real fitness (90 %
bootstrap interval), the mean absolute error and bias of the fitness, the Brier score of the fall
frequency, each over the K draws, and the ceiling the real trials' noise allows; and, for every
grounded world, how often the sim falls where the real robot fell when it is teacher-forced along
its own grounding walks (their real next states in place of the forward model). Writes
``fidelity.json``, ``fidelity.png`` (predicted vs real fitness, one colour per draw), ``table.txt``
into the run directory; re-running the same command resumes where it stopped, and re-running it
with more worlds or another ``--episodes`` measures only what is new (the first k episode seeds of a
gait are the same whatever the count). Every stochastic world is also scored from its first 1, 2,
4, ... episodes per gait: the table ends with fidelity against the number of episodes per gait
(``fidelity_episodes.png``), the figures runs with fewer ``--episodes`` would report. Before that,
paired tests of the rankings: ρ(world) − ρ(reference), the mean over the draws, with 90 % intervals
and p-values from a paired bootstrap over the real trials and episodes (this panel) and over the
gaits too (a new panel), for every world against the plain sim, every variant against its plain
kind, and SGAT − GAT, hybrid − identified, hybrid − SGAT.

World options after ':' (e.g. ``--worlds sgat sgat:ensemble=5 sgat:real=8``): ``alpha``,
``ensemble``, ``inverse_command`` (0/1), ``hidden`` (e.g. 64x64: the paper's tanh networks; 0: linear models, the default), ``epochs``, ``real`` and ``sim`` (walks
per draw), ``noise`` (exploration noise [rad]), ``gaits`` (walks spread over this many gaits),
``residual`` (0/1), ``matched`` (0/1: the matched transformer, a + f_sim^-1(s, ŝ_real) - f_sim^-1(s, ŝ_sim)), ``zero`` (0/1: linear models from zero weights), ``local`` (0/1: a joint-local inverse model, each joint's command from its own state only), ``mixture`` (K Gaussians in SGAT's forward model), ``memory`` (correlation time of SGAT's noise [s]), ``shadow`` (τ [s] of the shadow state the forward model predicts from; 0: the sim's state, the paper), ``state`` (legs, legs+imu), ``history`` (frames of state the models see; default 6; 1: the paper's
one frame), ``commands`` (c: the forward model also sees the c previous commands), ``gate`` (q in (0, 1]: the correction shrunk where the ensemble's members disagree more than the q-quantile of their disagreement on the real transitions they were fitted on), ``delay`` (d control steps: both models bridge an actuation delay of the sim, the forward model predicting s_{t+d+1} from the d previous commands and the inverse model answering it given the d actions sent before; ``auto`` for hybrid: the draw's identified latency in whole control steps) for gat, sgat and hybrid, ``method`` (sgat/gat) for hybrid; ``sigma`` for ane;
``terms`` and ``ground`` (0/1: ablations) for identified; ``stepping`` (stepping logs per identification), ``confounded`` (1: also the contact terms that only stand in for the identified uneven ground; default 0 since the fourteenth round), ``walkfit`` (actuation: torque limit, leg kp and latency; ground: latency and the ground's RMS height; fitted to the real walks of θ0) and ``servo`` (one kp scale common to every servo, fitted over the diagnosis's model to the in-air logs: air; the same with the stepping logs diagnosed again on top of it: staged; to the stepping logs: stepping; refit: as staged, fitted jointly with one dry and one viscous friction common to every joint and the in-air model's terms) for identified and hybrid; ``ane`` (σ [rad]: the ANE's noise added to the world's leg targets, the world of ``optimize --methods sgat+ane``) for gat, sgat, identified and hybrid.
The world ``oracle`` (not a default) is the real world itself on fresh seeds: the ρ a world that is
exactly right gets with the same number of episodes per gait; ``oracle:mean=1`` is the real world
with every effect fixed at the middle of its range (the terrain's amplitude too): what a world that
knows the real physics exactly, as one point and without its spread from episode to episode, gets. ``oracle:mean=1:engine=mujoco`` builds that mean physics into the MuJoCo sim
with the identified sim's effect models: what the identified world gets if the diagnosis finds every
effect exactly. ``ground=real`` walks that MuJoCo form on the real world's own lumpy terrain of each
episode seed, ``ground=model`` the PyBullet form on the identified sim's Gaussian surface of each
seed: the four mean-physics oracles tell the engines' gap from the ground model's. ``compliance=S``
(the ground contact's time constant [s], e.g. 0.004: what the diagnosis identifies) and
``backlash=0`` (no backlash terms, which the MuJoCo form builds as series play hinges) rebuild the
MuJoCo form with the two settings ``benchmarks/engine_gap_walks.py`` found it carries; ``drop=F+G``
leaves those effect families out of it (listed below): what an identified world that misses them
loses.
"""

from __future__ import annotations

import argparse
import os
import sys

from experiments.runtime.executors import make_executor
from experiments.fidelity.run import DEFAULT_WORLDS, Fidelity, FidelityConfig, format_phases, format_table
from experiments.runtime.tasks import MEAN_PHYSICS_FAMILIES
import experiments.cli.argtypes as A


def register(sub) -> argparse.ArgumentParser:
    p = sub.add_parser("fidelity", help="how well each training world predicts real gait fitness",
                       description=__doc__ + f"\nEffect families of drop=: {', '.join(MEAN_PHYSICS_FAMILIES)}.\n",
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    d = FidelityConfig()
    p.add_argument("--worlds", nargs="+", default=None, metavar="WORLD",
                   help=f"training worlds (default: {' '.join(DEFAULT_WORLDS)}; other robots than the NAO: without identified, hybrid; "
                        "also: oracle, the real world itself on fresh seeds)")
    p.add_argument("--gaits", type=A.count(0, 1000), default=d.gaits, help=f"gaits drawn around θ0 besides θ0 (default {d.gaits})")
    p.add_argument("--box", type=A.real(0.0, 1.0, open_lo=True), default=d.box,
                   help=f"half-width of the box the gaits are drawn in, normalized (default {d.box}: optimize's trust region)")
    p.add_argument("--params", type=A.in_file, nargs="+", default=[], metavar="THETA_JSON", help="more gaits: θ files (e.g. a run's thetas/*.json); every world is then also scored on "
                   "the drawn and the given gaits apart, and on each file name (every Table I seed's hybrid_step2)")
    p.add_argument("--real-trials", type=A.count(2, 10000), default=d.real_trials, help=f"paired real trials per gait (default {d.real_trials})")
    p.add_argument("--data-seeds", type=A.count(1, 100), default=d.data_seeds,
                   help=f"independent draws of the real data each learned world is fitted on (default {d.data_seeds})")
    p.add_argument("--episodes", type=A.count(1, 1000), default=d.episodes,
                   help=f"episodes per gait in a stochastic training world (default {d.episodes})")
    p.add_argument("--seconds", type=A.seconds, default=d.seconds, help=f"episode length [s] (default {d.seconds})")
    p.add_argument("--profile", default=d.profile, help=f"real-world effect profile: real, none, real-flat (real on flat ground) or real-ground (its uneven ground alone); default {d.profile}")
    p.add_argument("--identify-budget", type=A.real(0.0, 86400.0, unit='s'), default=d.identify_budget_s, metavar="SECONDS",
                   help=f"wall-clock time budget of each diagnosis of the identified worlds, a safety net: a budget "
                        f"that binds makes them depend on the machine's speed (default {d.identify_budget_s:g}; a "
                        "world's stepping-log diagnosis gets it per 3 logs)")
    p.add_argument("--identify-rounds", type=A.count(1, 100), default=d.identify_rounds, metavar="N",
                   help=f"screen/refit rounds of each diagnosis of the identified worlds (default {d.identify_rounds}; "
                        "1 saves about a third of the diagnoses' time, but leaves out the arm and head joints' "
                        "friction in the air, and the fitted latency absorbs it: docs/grounding_history.md, twenty-fourth round)")
    p.add_argument("--seed", type=A.seed, default=d.seed, help="seed of the panel, trials and data draws (default 0)")
    p.add_argument("--out", type=A.out_dir, help="run directory (default runs/fidelity-seed<seed>)")
    p.add_argument("--workers", type=A.workers, help="worker processes (default: one per core; 1 = serial)")
    p.add_argument("--ray-address", help="run episodes on a Ray cluster")
    A.add_robot(p)
    return p


def run(args) -> dict:
    for p in args.params:
        if not os.path.isfile(p):
            raise FileNotFoundError(f"--params: no such file {p!r}")
    worlds = args.worlds
    if worlds is None:  # the identified worlds are the NAO's (sgatwalk diagnose identifies the NAO)
        worlds = [w for w in DEFAULT_WORLDS if args.robot == "nao" or w not in ("identified", "hybrid")]
    cfg = FidelityConfig(worlds=tuple(worlds), gaits=args.gaits, box=args.box, params=tuple(args.params),
                         real_trials=args.real_trials, data_seeds=args.data_seeds, episodes=args.episodes,
                         seconds=args.seconds, profile=args.profile,
                         identify_budget_s=args.identify_budget, identify_rounds=args.identify_rounds, seed=args.seed,
                         robot=args.robot)
    cfg.validate()
    out = args.out or os.path.join("runs", f"fidelity-{'' if args.robot == 'nao' else args.robot + '-'}seed{args.seed}")
    log = lambda s: print(s, file=sys.stderr, flush=True)  # noqa: E731 - progress on stderr, also with --json
    with make_executor(args.workers, args.ray_address) as ex:
        res = Fidelity(cfg, out, ex, log=log, progress=not args.json).run()
    res["run_dir"] = out  # res["wall_s"]: the run's time over all its invocations (timing.json)
    if not args.json:
        print(format_table(res), flush=True)
        figs = "fidelity.png" + (", fidelity_episodes.png" if os.path.exists(os.path.join(out, "fidelity_episodes.png")) else "")
        print(f"run directory: {out} (fidelity.json, {figs}, table.txt)", flush=True)
        print(f"time: {res['wall_s'] / 60:.1f} min over the run's invocations ({format_phases(res['phases_s'])})",
              flush=True)
    return res
