"""``sgatwalk stochasticity``: does SGAT pull ahead of GAT as the real world's per-step randomness grows?

At each ``--levels`` level of per-step randomness (``--stochasticity``: servo torque noise per control
step, foot friction and contact softness per touchdown) runs ``sgatwalk fidelity`` of ``--worlds``
(how well each training world ranks gaits by real fitness, over ``--data-seeds`` draws of the real
data); at the lowest and highest level ``sgatwalk table1`` of ``--methods`` (``--seeds`` optimization
seeds, ``--trials`` paired real trials) and CMA-ES in the real world itself (``--real-seeds`` seeds, the
bound of what the walk engine reaches there). Writes ``study.json``, ``table.txt`` and
``stochasticity.png`` (fidelity per world against the level; SGAT - GAT real fitness and falls with
95 % intervals over seeds) in ``--out``, after every part; the parts are run directories of their
own, and the same command resumes where it stopped (more levels or Table I methods may be added to
a study later). The full default study takes about a day on 2 cores: use fewer levels, seeds or
--generations to fit a budget.
"""

from __future__ import annotations

import argparse
import os

import experiments.cli.argtypes as A


def register(sub) -> argparse.ArgumentParser:
    from experiments.stochasticity.run import StudyConfig  # imports no engine

    d = StudyConfig()
    p = sub.add_parser("stochasticity", help="SGAT vs GAT as the real world's per-step randomness grows",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--levels", type=A.levels, default=d.levels, metavar="LEVELS",
                   help=f"stochasticity levels of the fidelity runs (default {','.join(f'{v:g}' for v in d.levels)}; "
                        "none: Table I runs only)")
    p.add_argument("--table1-levels", type=A.levels, metavar="LEVELS",
                   help="levels of the Table I runs (default: the lowest and highest of --levels)")
    p.add_argument("--worlds", type=A.worlds, metavar="WORLDS", default=d.worlds,
                   help=f"fidelity worlds (default {','.join(d.worlds)})")
    p.add_argument("--gaits", type=A.count(2, 1000), default=d.gaits, help=f"fidelity panel gaits besides θ0 (default {d.gaits})")
    p.add_argument("--real-trials", type=A.count(2, 1000), default=d.real_trials,
                   help=f"fidelity real trials per gait (default {d.real_trials})")
    p.add_argument("--data-seeds", type=A.count(1, 100), default=d.data_seeds,
                   help=f"fidelity draws of the real data (default {d.data_seeds})")
    p.add_argument("--episodes", type=A.count(1, 1000), default=d.episodes,
                   help=f"fidelity episodes per gait in a stochastic world (default {d.episodes})")
    p.add_argument("--methods", type=A.worlds, metavar="WORLDS", default=d.methods,
                   help=f"Table I methods (default {','.join(d.methods)})")
    p.add_argument("--seeds", type=A.count(1, 100), default=d.seeds, help=f"Table I optimization seeds (default {d.seeds})")
    p.add_argument("--trials", type=A.count(2, 10000), default=d.trials, help=f"Table I paired real trials (default {d.trials})")
    p.add_argument("--real-seeds", type=A.count(0, 100), default=d.real_seeds,
                   help=f"seeds of CMA-ES in the real world, the bound (default {d.real_seeds}; 0: none)")
    p.add_argument("--check-episodes", type=A.count(0, 1000), default=d.check_episodes,
                   help=f"episodes of each SGAT and GAT gait in its own grounded world, beside its real fall rate "
                        f"(default {d.check_episodes}; 0: none)")
    p.add_argument("--popsize", type=A.count(2, 10000), help="CMA-ES population of each optimization (default: optimize's)")
    p.add_argument("--generations", type=A.count(1, 10000), help="CMA-ES generations per grounding step (default: optimize's)")
    p.add_argument("--seconds", type=A.seconds, default=d.seconds, help=f"episode length [s] (default {d.seconds:g})")
    p.add_argument("--seed", type=A.seed, default=0, help="run seed of every part (default 0)")
    p.add_argument("--out", type=A.out_dir, default=os.path.join("runs", "stochasticity"),
                   help="study directory (default runs/stochasticity)")
    A.add_executor(p)
    return p


def run(args):
    from experiments.runtime.executors import make_executor
    from experiments.runtime.progress import Reporter
    from experiments.stochasticity.run import Study, StudyConfig, format_table

    opt = {k: getattr(args, k) for k in ("popsize", "generations") if getattr(args, k) is not None}
    with A.user_input():
        cfg = StudyConfig(levels=args.levels, table1_levels=args.table1_levels, worlds=args.worlds, gaits=args.gaits,
                          real_trials=args.real_trials, data_seeds=args.data_seeds, episodes=args.episodes,
                          methods=args.methods, seeds=args.seeds, trials=args.trials, real_seeds=args.real_seeds,
                          check_episodes=args.check_episodes,
                          optimize=opt, seconds=args.seconds, seed=args.seed)
        study = Study(cfg, args.out, None, reporter=Reporter("stochasticity"))
    with make_executor(args.workers, args.ray_address) as ex:
        study.ex = ex
        res = study.run()
    res["out"] = args.out
    res["text"] = format_table(res)
    if not args.json:
        print(res["text"], flush=True)
        print(f"study directory: {args.out} (study.json, table.txt, stochasticity.png)", flush=True)
    return res
