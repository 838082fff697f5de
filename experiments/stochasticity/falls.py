"""Why the grounded worlds' gaits fall in the real world (a part of ``sgatwalk stochasticity``).

Two measurements, both on what a study has already saved:

* :func:`grounded_falls`: each Table I gait (the last grounding step's, per method and optimization
  seed) walked ``episodes`` times in the grounded world it was optimized in (the sim with that step's
  action transformer, :class:`experiments.runtime.tasks.EpisodeTask` ``transformer=``), beside its
  paired real trials of the Table I run: does the training world predict the gait's real fall rate?
* :func:`forward_calibration`: SGAT's forward model (the per-step Gaussian N(μ, σ²) of Δs the grounded
  world samples from, Desai et al., IROS 2020, Sec. III) against real transitions it was not fitted
  on: the fidelity run's models of one draw of the real data scored on the other draw's walks. Per
  state dimension the spread of z = (Δs - μ) / σ: 1 is calibrated, above 1 the model's σ is too small
  (too sure), below 1 too large.
"""

from __future__ import annotations

import glob
import json
import math
import os

import numpy as np

from common.files import atomic_write_text, jsonable
from experiments.runtime.progress import Reporter

#: Seed purpose of the grounded-world episodes (:func:`experiments.runtime.seeds.derive_seeds`).
GROUNDED = 47
#: z spread above which a state dimension counts as over-confident (σ at least a third too small).
OVERCONFIDENT = 1.5


def grounded_falls(table1_dir: str, run_dir: str, executor, *, methods=("sgat", "gat"), episodes: int = 20,
                   seed: int = 0, reporter: Reporter | None = None) -> dict:
    """Fall rate of each Table I gait in its own grounded world against the real one.

    Args:
        table1_dir: a finished ``sgatwalk table1`` run directory (``table1.json``, ``opt_seed<s>/``).
        run_dir: where the episodes go (``episodes.jsonl``, resumed) and the result (``falls.json``).
        executor: the executor of the episodes (``experiments.runtime.executors``).
        methods: grounded methods of the run to check (others are skipped).
        episodes: grounded-world episodes per gait.  seed: root seed of their episode seeds.

    Returns:
        ``{"methods": {method: {"step", "grounded": {falls, n, rate, ci95, fitness_mean}, "real": {...},
        "per_seed": [...]}}, "episodes", "seconds"}``; also written to ``run_dir/falls.json``.

    Raises:
        ValueError: ``table1_dir`` has no finished run, or a method of it has no transformer.
    """
    from common.defaults import EPISODE_SECONDS
    from experiments.runtime.rundir import EpisodeLog
    from experiments.runtime.seeds import derive_seeds
    from experiments.runtime.stats import wilson_interval
    from experiments.runtime.tasks import EpisodeTask
    from experiments.table1.run import last_step_gait

    report = reporter or Reporter.quiet()
    path = os.path.join(table1_dir, "table1.json")
    if not os.path.exists(path):
        raise ValueError(f"{table1_dir} holds no finished Table I run (no table1.json)")
    with open(path) as f:
        t1 = json.load(f)
    cfg = t1["config"]
    methods = [m for m in methods if m in cfg["methods"]]
    seconds = float(cfg.get("optimize", {}).get("seconds", EPISODE_SECONDS))
    seeds = derive_seeds(seed, GROUNDED, n=episodes)
    log = EpisodeLog(run_dir, {"table1": os.path.abspath(table1_dir), "methods": methods, "episodes": episodes,
                               "seed": seed}, "grounded-falls check", ignore=("table1",), reporter=report)
    gaits, tasks = {}, []
    for m in methods:
        for s in range(cfg["seeds"]):
            step, theta, model = last_step_gait(table1_dir, m, s)
            gaits[(m, s)] = step
            tasks += [EpisodeTask("sim", tuple(theta), sd, seconds, transformer=model, key=f"{m}|{s}|e{j}")
                      for j, sd in enumerate(seeds)]
    log.run(executor, tasks, "grounded-world episodes", report)
    real = {(r["method"], r["step"]): r for r in t1["rows"]}

    def rate(falls: int, n: int) -> dict:
        return {"falls": int(falls), "n": int(n), "rate": falls / n if n else math.nan,
                "ci95": list(wilson_interval(int(falls), int(n)))}

    out: dict = {"methods": {}, "episodes": episodes, "seconds": seconds}
    for m in methods:
        per = []
        for s in range(cfg["seeds"]):
            ep = [log.done[f"{m}|{s}|e{j}"] for j in range(episodes)]
            row = real[(m, gaits[(m, s)])]
            rs = next(p for p in row["per_seed"] if p["seed"] == s)
            per.append({"seed": s, "step": gaits[(m, s)],
                        "grounded": {**rate(sum(e["fell"] for e in ep), episodes),
                                     "fitness_mean": float(np.mean([e["fitness"] for e in ep]))},
                        "real": {**rate(rs["falls"], rs["n"]), "fitness_mean": rs["fitness_mean"]}})
        gf, gn = sum(p["grounded"]["falls"] for p in per), sum(p["grounded"]["n"] for p in per)
        rf, rn = sum(p["real"]["falls"] for p in per), sum(p["real"]["n"] for p in per)
        out["methods"][m] = {
            "grounded": {**rate(gf, gn), "fitness_mean": float(np.mean([p["grounded"]["fitness_mean"] for p in per]))},
            "real": {**rate(rf, rn), "fitness_mean": float(np.mean([p["real"]["fitness_mean"] for p in per]))},
            "per_seed": per}
    atomic_write_text(os.path.join(run_dir, "falls.json"), json.dumps(jsonable(out), indent=1))
    return out


def _z_stats(Y: np.ndarray, mu: np.ndarray, sd: np.ndarray) -> np.ndarray:
    """Per-dimension standard deviation of z = (Y - mu) / sd, shape (state dims,)."""
    return ((Y - mu) / sd).std(axis=0)


def forward_calibration(fidelity_dir: str, method: str = "sgat") -> dict:
    """Held-out calibration of a grounded world's forward model in a fidelity run.

    For every pair of data draws (d, e), d != e, the models fitted on draw d (``models/<method>-*_d<d>``)
    predict the real transitions of draw e's walks (``data/real_d<e>_*.parquet``, built as the grounding
    builds them, :func:`sgat.grounding.recording_transitions`). Each ensemble member's σ is what the
    grounded world samples with at each step (one member per episode).

    Args:
        fidelity_dir: a finished ``sgatwalk fidelity`` run with at least two data draws.
        method: the grounded world (``sgat``; ``hybrid`` and ``gat`` have forward models too).

    Returns:
        ``{"method", "dims": [names], "z_std": per-dimension z spread (members and pairs averaged),
        "median_z_std", "overconfident_share" (dimensions above :data:`OVERCONFIDENT`), "worst":
        [(name, z spread)] x 3, "mixture_median_z_std" (the members' equal mixture), "transitions"}``.

    Raises:
        ValueError: fewer than two draws with models and real data in ``fidelity_dir``.
    """
    from envs import ObservationLayout, Recording
    from robots import get_robot
    from sgat.grounding import recording_transitions
    from sgat.transformer import ActionTransformer

    with open(os.path.join(fidelity_dir, "config.json")) as f:
        robot = json.load(f).get("robot", "nao")
    layout = ObservationLayout(get_robot(robot))
    models = {}
    for p in sorted(glob.glob(os.path.join(fidelity_dir, "models", f"{method}-*_d*"))):
        models[int(p.rsplit("_d", 1)[1])] = p
    draws = [d for d in sorted(models) if glob.glob(os.path.join(fidelity_dir, "data", f"real_d{d}_*.parquet"))]
    if len(draws) < 2:
        raise ValueError(f"{fidelity_dir}: forward calibration needs two data draws with {method} models, "
                         f"found {len(draws)}")
    recs = {e: [Recording.from_parquet(p)
                for p in sorted(glob.glob(os.path.join(fidelity_dir, "data", f"real_d{e}_*.parquet")))]
            for e in draws}
    zs, zmix, zin, names, n = [], [], [], None, 0
    for d in draws:
        tr = ActionTransformer.load(models[d])
        names = list(tr.spec.state_names)
        for e in draws:
            t = recording_transitions(recs[e], layout, tr.spec, past=tr.forwards[0].commands, delay=tr.delay)
            X, Y = t.forward_input(), t.dS
            preds = [f.predict(X) for f in tr.forwards]
            if e == d:  # the model's own data: how well it fits what it was fitted on
                zin += [_z_stats(Y, mu, sd) for mu, sd in preds]
                continue
            n += len(Y)
            zs += [_z_stats(Y, mu, sd) for mu, sd in preds]
            mus, sds = np.stack([p[0] for p in preds]), np.stack([p[1] for p in preds])
            m = mus.mean(0)
            zmix.append(_z_stats(Y, m, np.sqrt(np.maximum((sds ** 2 + mus ** 2).mean(0) - m ** 2, 1e-30))))
    z = np.mean(zs, axis=0)
    order = np.argsort(-z)
    return {"method": method, "dims": names, "z_std": z.tolist(), "median_z_std": float(np.median(z)),
            "overconfident_share": float(np.mean(z > OVERCONFIDENT)),
            "worst": [(names[i], float(z[i])) for i in order[:3]],
            "mixture_median_z_std": float(np.median(np.mean(zmix, axis=0))),
            "in_sample_median_z_std": float(np.median(np.mean(zin, axis=0))), "transitions": int(n)}
