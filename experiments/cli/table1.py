"""``sgatwalk table1``: the paper's Table I with power -- several optimization seeds per method, every
gait on the same paired real trials, and paired tests between the methods.

Runs ``sgatwalk optimize`` (default settings) for every method and each of ``--seeds`` optimization
seeds, then walks θ0 and every resulting gait on the same ``--trials`` real trial seeds. Prints per
method and grounding step the speed mean ± s.e. [cm/s], falls with a Wilson 95 % interval and the
fitness, then paired tests at each step (a permutation test on fitness, McNemar's exact test on
falls; pairs = seed x trial) of SGAT vs GAT, SGAT vs the plain sim, hybrid vs SGAT, hybrid vs ANE, hybrid vs
identified, a grounded world vs the real world itself (only pairs of methods run) and every method vs θ0, each
with its fitness difference per optimization seed and a t-test over those (the seeds as the units:
whether the methods, not only these gaits, differ), and a verdict in words whichever way it falls.
Writes ``table1.json`` and ``table.txt``; the optimization runs live in ``opt_seed<s>/``. Re-running
the same command resumes where it stopped (the optimizations from their checkpoints, the evaluation
episode by episode); given more ``--seeds`` or ``--methods`` it adds them and walks only the new gaits.
"""

from __future__ import annotations

import argparse
import os

import experiments.cli.argtypes as A


def register(sub) -> argparse.ArgumentParser:
    from experiments.table1.config import Table1Config  # imports no engine

    d = Table1Config()
    p = sub.add_parser("table1", help="Table I with power: methods x optimization seeds on paired real trials",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--methods", type=A.worlds, metavar="WORLDS", default=d.methods,
                   help=f"comma list of training worlds (default {','.join(d.methods)}; any world of sgatwalk optimize, "
                        "e.g. real, identified, sgat:ane=0.05); more methods given to a run directory are added to it, "
                        "nothing done is redone")
    p.add_argument("--seeds", type=A.count(1, 100), default=d.seeds, help=f"optimization seeds per method (default {d.seeds})")
    p.add_argument("--trials", type=A.count(2, 10000), default=d.trials, help=f"paired real trials per gait (default {d.trials})")
    p.add_argument("--seed", type=A.seed, default=0, help="seed of the real trial seeds (default 0)")
    p.add_argument("--popsize", type=A.count(2, 10000), help="CMA-ES population of each optimization (default: optimize's)")
    p.add_argument("--generations", type=A.count(1, 10000), help="CMA-ES generations per grounding step (default: optimize's)")
    p.add_argument("--grounding-steps", type=A.count(1, 100), help="grounding steps (default: optimize's)")
    p.add_argument("--seconds", type=A.seconds, help="episode length [s] (default 7.5)")
    A.add_profile(p)
    p.add_argument("--baseline", type=A.in_file, help="an earlier run's table1.json on the same real trials: "
                   "pair every row with it (e.g. another grounding setting)")
    p.add_argument("--out", type=A.out_dir, default=os.path.join("runs", "table1"), help="run directory (default runs/table1)")
    A.add_executor(p)
    return p


def optimize_overrides(args) -> dict:
    """The :class:`experiments.optimize.OptimizeConfig` settings given on the command line (the rest stay
    optimize's defaults)."""
    given = {k: getattr(args, k) for k in ("popsize", "generations", "grounding_steps", "seconds", "profile")
             if getattr(args, k, None) is not None}
    if args.stochasticity:  # runs at level 0 keep the settings they were saved with
        given["stochasticity"] = args.stochasticity
    return given


def run(args):
    from experiments.runtime.executors import make_executor
    from experiments.runtime.progress import Reporter
    from experiments.runtime.rundir import check_run_dir
    from experiments.table1.config import Table1Config
    from experiments.table1.run import Table1, format_table, load_baseline

    with A.user_input():
        cfg = Table1Config(methods=args.methods, seeds=args.seeds, trials=args.trials, seed=args.seed,
                           optimize=optimize_overrides(args), baseline=args.baseline)
        cfg.validate()
        if cfg.baseline is not None:
            load_baseline(cfg.baseline, cfg)
        check_run_dir(args.out, cfg.to_dict(), "Table I run", ignore=cfg.RESUMABLE)
    with make_executor(args.workers, args.ray_address) as ex:
        res = Table1(cfg, args.out, ex, reporter=Reporter("table1")).run()
    res["run_dir"] = args.out  # res["wall_s"]: the run's time over all its invocations (timing.json)
    if not args.json:
        print(format_table(res), flush=True)
        print(f"run directory: {args.out} (table1.json, table.txt)", flush=True)
    return res
