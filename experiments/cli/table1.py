"""``sgatwalk table1``: the paper's Table I with power -- several optimization seeds per method, every
gait on the same paired real trials, and paired tests between the methods.

Runs ``sgatwalk optimize`` (default settings) for every method and each of ``--seeds`` optimization
seeds, then walks θ0 and every resulting gait on the same ``--trials`` real trial seeds. Prints per
method and grounding step the speed mean ± s.e. [cm/s], falls with a Wilson 95 % interval and the
fitness, then paired tests at each step (a permutation test on fitness, McNemar's exact test on
falls; pairs = seed x trial) of SGAT vs GAT, SGAT vs none, hybrid vs SGAT, hybrid vs ANE, hybrid vs
identified (``experiments.table1.run.comparisons``: only pairs of methods run) and every method vs θ0, each
with its fitness difference per optimization seed and a t-test over those (the seeds as the units:
whether the methods, not only these gaits, differ), and a verdict in words whichever way it falls.
Writes ``table1.json`` and ``table.txt``; the optimization runs live in ``opt_seed<s>/``. Re-running
the same command resumes where it stopped (the optimizations from their checkpoints, the evaluation
episode by episode); given more ``--seeds`` or ``--methods`` it adds them and walks only the new gaits.
"""

from __future__ import annotations

import argparse
import os
import sys

from experiments.runtime.executors import make_executor
from experiments.table1.run import Table1, Table1Config, format_table
import experiments.cli.argtypes as A


def register(sub) -> argparse.ArgumentParser:
    p = sub.add_parser("table1", help="Table I with power: methods x optimization seeds on paired real trials",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    d = Table1Config()
    p.add_argument("--methods", default=",".join(d.methods), help=f"comma list (default {','.join(d.methods)}); also "
                   "identified, sgat+ane, gat+ane, identified+ane, hybrid+ane (that method's world with the ANE's noise "
                   "added); more methods given to a run directory are added to it, nothing done is redone")
    p.add_argument("--seeds", type=A.count(1, 100), default=d.seeds, help=f"optimization seeds per method (default {d.seeds})")
    p.add_argument("--trials", type=A.count(2, 10000), default=d.trials, help=f"paired real trials per gait (default {d.trials})")
    p.add_argument("--seed", type=A.seed, default=d.seed, help="seed of the real trial seeds (default 0)")
    p.add_argument("--popsize", type=A.count(2, 10000), help="CMA-ES population of each optimization (default: optimize's)")
    p.add_argument("--generations", type=A.count(1, 10000), help="CMA-ES generations per grounding step (default: optimize's)")
    p.add_argument("--grounding-steps", type=A.count(1, 100), help="grounding steps (default: optimize's)")
    p.add_argument("--seconds", type=A.seconds, help="episode length [s] (default 7.5)")
    p.add_argument("--hidden", type=A.hidden_layers, help="hidden layers of the grounding models, e.g. 64x64 "
                   "(default: optimize's, 0 = linear)")
    p.add_argument("--history", type=A.count(1, 10), help="frames of state history the grounding models see "
                   "(default: optimize's)")
    p.add_argument("--command-history", type=A.count(0, 10), help="previous commands the forward model also sees "
                   "(default: optimize's)")
    p.add_argument("--matched", action="store_true", default=None,
                   help="ground with the matched transformer (default: optimize's)")
    p.add_argument("--local-inverse", dest="local_inverse", action="store_true", default=None,
                   help="ground with a joint-local inverse model (default: optimize's)")
    p.add_argument("--zero-init", dest="zero_init", action="store_true", default=None,
                   help="fit the linear grounding models from zero weights (default: optimize's)")
    p.add_argument("--shadow", type=A.real(0.0, 10.0, unit="s"),
                   help="τ [s] of the transformer's shadow state (default: optimize's)")
    p.add_argument("--confounded-terms", dest="identified_confounded", action="store_true", default=None,
                   help="hybrid: also build in the contact terms the diagnosis could not tell apart from the uneven "
                        "ground (default: optimize's, off)")
    p.add_argument("--identify-rounds", type=A.count(1, 100), metavar="N",
                   help="hybrid: screen/refit rounds of each diagnosis (default: optimize's, 2)")
    p.add_argument("--ane-sigma", type=A.real(0.0, 1.0, unit="rad"),
                   help="the ANE's noise [rad], of ane and of every <method>+ane (default: optimize's, 0.05)")
    p.add_argument("--baseline", type=A.in_file, help="an earlier run's table1.json on the same real trials: "
                   "pair every row with it (e.g. another grounding setting)")
    p.add_argument("--out", type=A.out_dir, default=os.path.join("runs", "table1"), help="run directory (default runs/table1)")
    p.add_argument("--workers", type=A.workers, help="worker processes (default: one per core; 1 = serial)")
    p.add_argument("--ray-address", help="run episodes on a Ray cluster")
    return p


def optimize_overrides(args) -> dict:
    """The :class:`experiments.optimize.run.OptimizeConfig` settings given on the command line (the rest
    stay optimize's defaults)."""
    return {k: v for k, v in (("popsize", args.popsize), ("generations", args.generations),
                             ("grounding_steps", args.grounding_steps), ("seconds", args.seconds),
                             ("hidden", None if args.hidden is None else list(args.hidden)),
                             ("history", args.history), ("command_history", args.command_history),
                             ("matched", args.matched), ("local_inverse", args.local_inverse),
                             ("zero_init", args.zero_init), ("shadow", args.shadow),
                             ("identified_confounded", args.identified_confounded), ("identify_rounds", args.identify_rounds),
                             ("ane_sigma", args.ane_sigma))
            if v is not None}


def run(args) -> dict:
    opt = optimize_overrides(args)
    cfg = Table1Config(methods=tuple(m.strip() for m in args.methods.split(",") if m.strip()), seeds=args.seeds,
                       trials=args.trials, seed=args.seed, optimize=opt, baseline=args.baseline)
    cfg.validate()
    log = lambda s: print(s, file=sys.stderr, flush=True)  # noqa: E731 - progress on stderr, also with --json
    with make_executor(args.workers, args.ray_address) as ex:
        res = Table1(cfg, args.out, ex, log=log, progress=not args.json).run()
    res["run_dir"] = args.out  # res["wall_s"]: the run's time over all its invocations (timing.json)
    if not args.json:
        print(format_table(res), flush=True)
        print(f"run directory: {args.out} (table1.json, table.txt)", flush=True)
    return res
