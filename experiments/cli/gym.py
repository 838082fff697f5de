"""``sgatwalk gym``: Sim-to-NoisySim / Sim-to-NoisyReal on MuJoCo InvertedPendulum and HalfCheetah
with TRPO -- sim only, GAT, SGAT, ANE and real-trained (SGAT paper §IV.B, Figs. 8-9).

The grid of (noise, method, run) jobs runs through the executor (a local process pool by
default, Ray with --ray-address); every finished job's rows are appended to
OUT/results.parquet, so running the same command again resumes an interrupted sweep (finished
cells are skipped; changing a budget starts fresh cells). OUT also holds config.json,
summary.csv, table.txt, the figure gym_<env>_<experiment>.png and the trained policies.
"""

from __future__ import annotations

import argparse
import math
import os
import time
from pathlib import Path

from experiments.runtime.executors import make_executor
from experiments.runtime.progress import Reporter
from experiments.gym.config import EXPERIMENTS, METHODS, PRESETS, GymConfig
import experiments.cli.argtypes as A


def _floats(text: str, flag: str) -> tuple[float, ...]:
    out = []
    for part in str(text).split(","):
        part = part.strip()
        if not part:
            continue
        try:
            v = float(part)
        except ValueError:
            raise ValueError(f"{flag}: {part!r} is not a number (expected a comma list such as 0,0.1,0.3)") from None
        if not math.isfinite(v) or v < 0:
            raise ValueError(f"{flag}: {v:g} must be a finite value >= 0 (share of the action half-range)")
        out.append(round(v, 9))
    if not out:
        raise ValueError(f"{flag}: no values in {text!r}")
    return tuple(out)


def register(sub) -> argparse.ArgumentParser:
    p = sub.add_parser("gym", help="GAT/SGAT/ANE sim-to-real on MuJoCo InvertedPendulum and HalfCheetah (TRPO)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--env", default="InvertedPendulum", help="InvertedPendulum (default) or HalfCheetah")
    p.add_argument("--experiment", choices=EXPERIMENTS, default="noisyreal",
                   help="noisyreal (noise + mass change, default) or noisysim (noise only)")
    p.add_argument("--noise", help="comma list of real action-noise σ, share of the action half-range "
                                   "(default: the preset's, quick 0,0.3; paper 0,0.1,0.2,0.3)")
    p.add_argument("--methods", default=",".join(METHODS), help=f"comma list of {', '.join(METHODS)} (default all)")
    p.add_argument("--runs", type=A.count(1, 1000), help="independent training runs per cell (default: quick 2, paper 10)")
    p.add_argument("--preset", choices=sorted(PRESETS), default="quick",
                   help="training budgets: quick (default; minutes) or paper (the GARAT/SGAT code's budgets; hours)")
    p.add_argument("--seed", type=A.seed, help="base seed (default 0)")
    p.add_argument("--out", type=A.out_dir, help="sweep directory (default runs/gym_<env>_<experiment>_<preset>)")
    A.add_executor(p)
    p.add_argument("--pole-factor", type=A.real(0.0, 1000.0, open_lo=True), help="InvertedPendulum: real pole mass/inertia factor (default 10, "
                                                    "the paper; the GARAT code's 100 kg pole is ≈20)")
    p.add_argument("--mass-factor", type=A.real(0.0, 1000.0, open_lo=True), help="HalfCheetah: real mass/inertia factor (default 20/14)")
    p.add_argument("--ane-grid", help="ANE noise σ values tried (default: quick 0.1,0.3; paper 0.1,0.2,0.3,0.5)")
    p.add_argument("--sim-steps", type=A.count(1, 100_000_000), help="TRPO steps of the initial sim policy")
    p.add_argument("--grounded-steps", type=A.count(1, 100_000_000), help="TRPO steps per grounding step (GAT/SGAT) and for ANE")
    p.add_argument("--real-steps", type=A.count(1, 100_000_000), help="TRPO steps of the real-trained upper bound")
    p.add_argument("--grounding-steps", type=A.count(1, 1000), help="grounding steps (default: IP 1, HC 5 in the paper preset)")
    p.add_argument("--real-transitions", type=A.count(1, 100_000_000), help="real transitions collected per grounding step")
    p.add_argument("--sim-transitions", type=A.count(1, 100_000_000), help="sim transitions (with exploration noise) per grounding step")
    p.add_argument("--explore-sigma", type=A.real(0.0, 10.0), help="exploration noise of the sim data (default 0.3)")
    p.add_argument("--eval-episodes", type=A.count(1, 1_000_000), help="real episodes per policy evaluation")
    p.add_argument("--alpha", type=A.fraction, help="blend ã = (1-α)a + α g(s,a) (default 1, the paper's formula)")
    p.add_argument("--model-epochs", type=A.count(1, 100000), help="max epochs of the forward/inverse model fits")
    p.add_argument("--report", action="store_true", help="only rebuild table and figure from OUT/results.parquet")
    return p


def config_from_args(args):
    methods = tuple(m.strip().lower() for m in args.methods.split(",") if m.strip())
    over = dict(
        experiment=args.experiment, methods=methods, runs=args.runs, seed=args.seed,
        noise=_floats(args.noise, "--noise") if args.noise else None,
        ane_grid=_floats(args.ane_grid, "--ane-grid") if args.ane_grid else None,
        pole_factor=args.pole_factor, mass_factor=args.mass_factor, sim_steps=args.sim_steps,
        grounded_steps=args.grounded_steps, real_steps=args.real_steps, grounding_steps=args.grounding_steps,
        real_transitions=args.real_transitions, sim_transitions=args.sim_transitions,
        explore_sigma=args.explore_sigma, eval_episodes=args.eval_episodes, alpha=args.alpha,
        model_epochs=args.model_epochs)
    return GymConfig.from_preset(args.env, args.preset, **over)


def run(args) -> dict:
    from experiments.gym import run as G  # lazy: keeps sgatwalk --help fast

    with A.user_input():
        cfg = config_from_args(args)
    out = args.out or os.path.join("runs", f"gym_{cfg.env}_{cfg.experiment}_{cfg.preset}")
    log = (lambda *a, **k: None) if args.json else print
    if args.report:
        table = G.ResultTable(Path(out))
        with A.user_input():
            if not table.path.exists():
                raise FileNotFoundError(f"--report: no results table at {table.path}")
            rows = table.current(cfg)
            if not rows:
                raise ValueError(f"--report: {table.path} has no rows for these settings; give the options "
                                 f"the sweep ran with")
        summary = G.summarize(rows, cfg)
        paired = G.paired_differences(rows, cfg)
        text = G.format_table(summary, cfg, paired)
        fig = Path(out) / f"gym_{cfg.env}_{cfg.experiment}.png"
        G.plot_bars(summary, cfg, fig)
        G._write_text(Path(out) / "table.txt", text + "\n")
        G.write_summary_csv(summary, Path(out) / "summary.csv")
        log(text)
        log(f"wrote {fig}")
        return {"summary": summary, "paired": paired, "table": text, "files": {"figure": str(fig)},
                "config": cfg.to_dict()}

    ex = make_executor(args.workers, args.ray_address)
    t0 = time.perf_counter()
    try:
        res = G.run_sweep(cfg, out, ex, reporter=Reporter("gym"), log=log)
    finally:
        ex.close()
    res["wall_s"] = time.perf_counter() - t0
    res["config"] = cfg.to_dict()
    res["executor"] = {"name": ex.name, "workers": ex.workers}
    try:
        res["load_average"] = list(os.getloadavg())
    except OSError:  # pragma: no cover
        res["load_average"] = None
    log(res["table"])
    log(f"{res['tasks']} jobs ({res['new_rows']} new result rows) in {res['wall_s'] / 60:.1f} min on "
        f"{ex.name} x{ex.workers}; wrote {out}/results.parquet, summary.csv, table.txt, {res['files']['figure']}")
    return res
