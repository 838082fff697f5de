"""``sgatwalk optimize``: ground the sim on real data and optimize the gait with CMA-ES (the main job).

Runs Algorithm 1 of the SGAT paper for the NAO walk (see ``experiments/optimize/run.py``): per
grounding step, real and sim walks with the current gait, model fitting, CMA-ES over the 16
normalized gait parameters in the grounded sim, and 10 real-world trials of the result. The default
method is ``hybrid`` (SGAT grounding on the sim with the physics a diagnosis identified from
excitation logs of the real world, done once per run first); ``--methods sgat`` is the paper's. Prints the
paper's Table I (speed mean ± std in cm/s, falls out of 10) with the θ0 row first.

The run directory holds config.yaml, generations.csv, evals.parquet, cma_state.pkl (replaced
atomically after every generation), models/, thetas/ (best θ per method and step as JSON),
data/ (the recordings used for grounding), fitness.png, table.txt and results.json.
``--resume RUN_DIR`` continues a killed run exactly where it stopped; ``--resume RUN_DIR --methods M``
adds the methods M to a run (on its seeds and real data) and runs them.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time

from experiments.runtime.executors import make_executor
from experiments.optimize.run import METHODS, PRESETS, OptimizeConfig, Optimizer, default_methods
import experiments.cli.argtypes as A


def register(sub) -> argparse.ArgumentParser:
    p = sub.add_parser("optimize", help="grounding (hybrid: SGAT on the identified sim) + CMA-ES gait optimization (the main job)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    d = OptimizeConfig()
    p.add_argument("--methods", help=f"comma list of {', '.join(METHODS)}. Default hybrid: SGAT grounding on "
                   "the sim with the physics identified from excitation logs of the real world (identified and hybrid "
                   "identify it first, ~2 min); sgat (the paper's SGAT on the plain sim) for robots other than the NAO. "
                   "sgat+ane, gat+ane, identified+ane or hybrid+ane: that method's world with the ANE's noise "
                   "(--ane-sigma) added; with --resume: methods to add to the run")
    p.add_argument("--preset", choices=sorted(PRESETS), default="quick",
                   help="quick (default; README: measured time) or paper (population 150, 2 grounding steps)")
    p.add_argument("--grounding-steps", type=A.count(1, 100), help=f"grounding steps (default {d.grounding_steps})")
    p.add_argument("--popsize", type=A.count(2, 10000), help=f"CMA-ES population (default {d.popsize})")
    p.add_argument("--generations", type=A.count(1, 10000), help=f"CMA-ES generations per grounding step (default {d.generations})")
    p.add_argument("--sigma0", type=A.real(0.0, 1.0, open_lo=True), help=f"initial CMA-ES step size on [0,1]-normalized params (default {d.sigma0})")
    p.add_argument("--trust-region", type=A.real(0.0, 1.0, open_lo=True), help=f"CMA-ES search box ±r around θ_i, normalized (default {d.trust_region}; 1 = off)")
    p.add_argument("--episodes-per-candidate", type=A.count(1, 1000), help=f"episodes per candidate (default {d.episodes_per_candidate})")
    p.add_argument("--seconds", type=A.seconds, help=f"episode length [s] (default {d.seconds})")
    p.add_argument("--real-episodes", type=A.count(1, 10000), help=f"real walks per grounding step (default {d.real_episodes})")
    p.add_argument("--sim-episodes", type=A.count(1, 10000), help=f"sim walks with exploration noise per step (default {d.sim_episodes})")
    p.add_argument("--exploration-noise", type=A.real(0.0, 1.0, unit='rad'), help=f"sim data action noise [rad] (default {d.exploration_noise})")
    p.add_argument("--select-episodes", type=A.count(1, 1000), help=f"episodes on which the CMA-ES mean, best candidate and θ_i "
                   f"are compared to pick θ_i+1 (default {d.select_episodes})")
    p.add_argument("--eval-trials", type=A.count(0, 10000), help=f"real trials per evaluation (default {d.eval_trials}; 0: none)")
    p.add_argument("--profile", help=f"real-world effect profile: real, none, real-flat (real on flat ground) or real-ground (its uneven ground alone); default {d.profile}")
    p.add_argument("--grounding-state", choices=["legs", "legs+imu"], help="grounding state (default legs)")
    p.add_argument("--history", type=A.count(1, 10), help="frames of state history the forward and inverse models see "
                   f"(default {d.history}; 1: the paper's one frame)")
    p.add_argument("--command-history", type=A.count(0, 10), help="previous commands the forward model also sees "
                   f"(default {d.command_history}: the paper's one-step model; 3: 30 ms, room for an actuation latency)")
    p.add_argument("--matched", action="store_true", default=None,
                   help="the matched transformer: a + f_sim^-1(s, ŝ_real) - f_sim^-1(s, ŝ_sim), with a forward model of "
                   "the sim (default off: the paper's f_sim^-1(s, ŝ_real))")
    p.add_argument("--local-inverse", dest="local_inverse", action="store_true", default=None,
                   help="a joint-local inverse model: each joint's command from its own angle and velocity only "
                   "(linear models; best with --matched; default off: the paper's inverse model of the whole state)")
    p.add_argument("--zero-init", dest="zero_init", action="store_true", default=None,
                   help="linear grounding models fitted from zero weights, not PyTorch's random ones (default off)")
    p.add_argument("--shadow", type=A.real(0.0, 10.0, unit="s"),
                   help=f"τ [s] of the transformer's shadow state: the forward model predicts from it and it relaxes "
                   f"toward the sim's state over τ (default {d.shadow:g}: the paper, from the sim's state; 0.02 "
                   "forecast better around θ0 but optimized worse in Table I: docs/grounding_history.md, ninth round)")
    p.add_argument("--alpha", type=A.fraction, help=f"blend ã = (1-α) a + α g(s,a) of raw and grounded action (default {d.alpha}; "
                   "1 = the paper's formula)")
    p.add_argument("--hybrid-alpha", type=A.fraction, help=f"blend of the hybrid method (default {d.hybrid_alpha})")
    p.add_argument("--ensemble", type=A.count(1, 100), help=f"forward/inverse model pairs; SGAT draws one per episode (default {d.ensemble})")
    p.add_argument("--inverse-command", dest="inverse_command", action="store_true", default=None,
                   help="the inverse model also sees the commanded action (default off)")
    p.add_argument("--hidden", type=A.hidden_layers, help="hidden layers of the forward and inverse models, e.g. 64x64 "
                   "(the paper's tanh networks); 0: linear models (default; README, sgatwalk fidelity)")
    p.add_argument("--model-epochs", type=A.count(1, 100000), help=f"max training epochs of each model (default {d.model_epochs})")
    p.add_argument("--no-aggregate", dest="aggregate", action="store_false", default=None,
                   help="fit each grounding step's models on θ_i's walks only (default: on the walks of "
                        "every θ_j so far, as the GARAT code accumulates data)")
    p.add_argument("--confounded-terms", dest="identified_confounded", action="store_true", default=None,
                   help="identified and hybrid: also build in the contact terms the diagnosis could not tell apart "
                        "from the uneven ground (default off since the fourteenth fidelity round; docs/grounding_history.md)")
    p.add_argument("--identify-rounds", type=A.count(1, 100), metavar="N",
                   help=f"identified and hybrid: screen/refit rounds of each diagnosis (default {d.identify_rounds}; 1 is "
                        "faster and leaves out the arm joints' friction: docs/grounding_history.md, twenty-fourth round)")
    p.add_argument("--ane-sigma", type=A.real(0.0, 1.0, unit='rad'), help=f"ANE action noise [rad] (default {d.ane_sigma})")
    p.add_argument("--params", type=A.in_file, help="initial gait parameters θ0 (JSON; default: the walk engine's θ0)")
    p.add_argument("--seed", type=A.seed, help="run seed (default 0)")
    p.add_argument("--out", type=A.out_dir, help="run directory (default runs/optimize_<methods>_<time>)")
    p.add_argument("--resume", type=A.in_path, metavar="RUN_DIR", help="continue a stopped run")
    p.add_argument("--workers", type=A.workers, help="worker processes (default: one per core; 1 = serial)")
    p.add_argument("--ray-address", help="run episodes on a Ray cluster (e.g. auto, local, ray://host:10001)")
    p.add_argument("--rerun", action="store_true", help="log selected candidates and real trials as .rrd files")
    A.add_robot(p)
    return p


def config_from_args(args) -> OptimizeConfig:
    kw = dict(PRESETS[args.preset])
    fields = {f.name for f in dataclasses.fields(OptimizeConfig)}
    for name in fields:
        v = getattr(args, name, None)
        if v is not None and name != "methods":
            kw[name] = v
    kw["methods"] = _methods(args.methods) if args.methods else default_methods(kw.get("robot", "nao"))
    cfg = OptimizeConfig(**kw)
    cfg.validate()
    if cfg.params and not os.path.exists(cfg.params):
        raise FileNotFoundError(f"--params: no such file {cfg.params!r}")
    return cfg


def _methods(text: str) -> tuple:
    return tuple(m.strip() for m in text.split(",") if m.strip())


def run(args) -> dict:
    add = _methods(args.methods) if args.resume and args.methods else ()  # checked by OptimizeConfig.validate
    if args.resume:
        cfg, run_dir = OptimizeConfig(), args.resume
        if not os.path.isdir(run_dir):
            raise FileNotFoundError(f"--resume: no run directory {run_dir!r}")
    else:
        cfg = config_from_args(args)
        who = "" if cfg.robot == "nao" else f"{cfg.robot}_"
        run_dir = args.out or os.path.join("runs", f"optimize_{who}{'-'.join(cfg.methods)}_{time.strftime('%Y%m%d-%H%M%S')}")

    def log(msg: str) -> None:  # progress and stage lines on stderr (stdout: the table, or the JSON)
        print(msg, file=sys.stderr, flush=True)
    ex = make_executor(args.workers, args.ray_address)
    t0 = time.perf_counter()
    try:
        res = Optimizer(cfg, run_dir, ex, progress=not args.json, log=log, rerun=args.rerun).run(resume=bool(args.resume), add_methods=add)
    finally:
        ex.close()
    res["wall_s"] = time.perf_counter() - t0
    res["robot"] = Optimizer.load_state(run_dir)["config"].get("robot", "nao")
    if not args.json:
        print(res["table"], flush=True)
        print(f"run directory: {run_dir} ({res['wall_s'] / 60:.1f} min)", flush=True)
    return res
