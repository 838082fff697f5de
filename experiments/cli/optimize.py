"""``sgatwalk optimize``: ground the sim on real data and optimize the gait with CMA-ES (the main job).

Algorithm 1 of the SGAT paper for the walking humanoid: per grounding step, real and sim walks
with the current gait, the forward and inverse models fitted, CMA-ES over the 16 normalized gait
parameters in the grounded sim, and real-world trials of the result. Prints the paper's Table I
(speed mean ± std in cm/s, falls) with the θ0 row first.

Methods are training worlds, written as everywhere in sgatwalk (docs/concepts/worlds.md):
  hybrid (default)   SGAT grounding on the sim with the physics a diagnosis identified from
                     excitation logs of the real world (identified first, about 2 min)
  sgat, gat          the paper's grounding of the plain sim (stochastic / deterministic)
  sim, ane           the plain sim; the sim with Gaussian noise on the leg targets
  identified         the identified sim without grounding
  real               CMA-ES in the real world itself (the bound; slow)
and options after ':', e.g. sgat:alpha=0.3, hybrid:ensemble=1, sgat:ane=0.05.

The run directory holds config.yaml, cma_state.pkl (replaced atomically after every generation),
generations.csv, evals.parquet, results.json, table.txt, fitness.png, models/, thetas/ (θ per method
and step as JSON) and data/ (the grounding walks). --resume RUN_DIR continues a stopped run exactly
where it stopped; --resume RUN_DIR --methods M adds the methods M to a run (its seeds and real data).
"""

from __future__ import annotations

import argparse
import os
import time

import experiments.cli.argtypes as A


def register(sub) -> argparse.ArgumentParser:
    from experiments.optimize.config import PRESETS, OptimizeConfig  # the config imports no engine

    p = sub.add_parser("optimize", help="grounding (hybrid: SGAT on the identified sim) + CMA-ES gait optimization (the main job)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    d = OptimizeConfig()
    p.add_argument("--methods", type=A.worlds, metavar="WORLDS",
                   help="comma list of training worlds (default hybrid; sgat for robots other than the NAO); with "
                        "--resume: methods to add to the run")
    p.add_argument("--preset", choices=sorted(PRESETS), default="quick",
                   help="quick (default) or paper (population 150, 20 generations, 10 real and 10 sim walks per step)")
    p.add_argument("--grounding-steps", type=A.count(1, 100), help=f"grounding steps (default {d.grounding_steps})")
    p.add_argument("--popsize", type=A.count(2, 10000), help=f"CMA-ES population (default {d.popsize})")
    p.add_argument("--generations", type=A.count(1, 10000), help=f"CMA-ES generations per grounding step (default {d.generations})")
    p.add_argument("--sigma0", type=A.real(0.0, 1.0, open_lo=True),
                   help=f"initial CMA-ES step size on [0,1]-normalized params (default {d.sigma0})")
    p.add_argument("--trust-region", type=A.real(0.0, 1.0, open_lo=True),
                   help=f"CMA-ES search box ±r around θ_i, normalized (default {d.trust_region}; 1 = off)")
    p.add_argument("--episodes-per-candidate", type=A.count(1, 1000), help=f"episodes per candidate (default {d.episodes_per_candidate})")
    p.add_argument("--select-episodes", type=A.count(1, 1000), help="episodes on which the CMA-ES mean, best candidate and θ_i "
                   f"are compared to pick θ_i+1 (default {d.select_episodes})")
    p.add_argument("--eval-trials", type=A.count(0, 10000), help=f"real trials per evaluation (default {d.eval_trials}; 0: none)")
    p.add_argument("--seconds", type=A.seconds, help=f"episode length [s] (default {d.seconds})")
    A.add_profile(p)
    p.add_argument("--no-aggregate", dest="aggregate", action="store_false", default=None,
                   help="fit each grounding step on θ_i's walks only (default: on every θ_j's so far, as the GARAT code)")
    p.add_argument("--params", type=A.in_file, help="initial gait parameters θ0 (JSON; default: the walk engine's θ0)")
    p.add_argument("--seed", type=A.seed, help="run seed (default 0)")
    p.add_argument("--out", type=A.out_dir, help="run directory (default runs/optimize_<methods>_<time>)")
    p.add_argument("--resume", type=A.in_dir, metavar="RUN_DIR", help="continue a stopped run")
    p.add_argument("--rerun", action="store_true", help="log selected candidates and real trials as .rrd files")
    A.add_executor(p)
    A.add_robot(p)
    return p


def config_from_args(args):
    """The :class:`experiments.optimize.config.OptimizeConfig` of the command line (preset, then options)."""
    from experiments.optimize.config import OptimizeConfig, with_preset

    fields = set(OptimizeConfig.__dataclass_fields__) - {"methods"}
    given = {k: getattr(args, k) for k in fields if getattr(args, k, None) is not None}
    return with_preset(args.preset, methods=args.methods, **given)


def run(args):
    from experiments.optimize.run import Optimizer  # lazy: loads the engines and torch
    from experiments.runtime.executors import make_executor
    from experiments.runtime.progress import Reporter

    with A.user_input():
        if args.resume:
            from experiments.optimize.config import OptimizeConfig

            Optimizer.load_state(args.resume)  # a readable checkpoint of this version, or a clear error
            cfg, run_dir = OptimizeConfig(), args.resume
        else:
            cfg = config_from_args(args)
            who = "" if cfg.robot == "nao" else f"{cfg.robot}_"
            names = "-".join(m.split(":")[0] for m in cfg.methods)
            run_dir = args.out or os.path.join("runs", f"optimize_{who}{names}_{time.strftime('%Y%m%d-%H%M%S')}")
    ex = make_executor(args.workers, args.ray_address)
    try:
        res = Optimizer(cfg, run_dir, ex, reporter=Reporter("optimize"), rerun=args.rerun).run(
            resume=bool(args.resume), add_methods=args.methods if args.resume and args.methods else ())
    finally:
        ex.close()
    if not args.json:
        print(res.table, flush=True)
        print(f"run directory: {run_dir} ({res.wall_s / 60:.1f} min)", flush=True)
    return res
