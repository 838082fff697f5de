"""Which effect of the real world lengthens the in-air latency a diagnosis fits, and what takes it out.

The identified world's in-air diagnosis puts the command latency at 16-27 ms where the real world
draws 10-20 ms per episode (docs/findings/grounding-variants.md). This measures why, with the truth
known: for each condition, three in-air (fixed-base) excitation logs of 6 s are recorded in the
PyBullet real world with a fixed 15 ms delay and one other effect of the ``"real"`` profile at its
range (or all of them), and three fits are made on them (``sysid.diagnose.fit_terms``, the engine-gap
calibration that ships with the package under every replay):

* ``latency``: the latency alone (what a diagnosis that keeps no other term fits);
* ``+ kp``: the latency with one kp scale common to every servo (``pd_gain_all``);
* ``+ kp + friction``: also one dry and one viscous friction on every joint (``coulomb_friction_all``,
  ``viscous_damping_all``; what ``identified:servo=refit`` fitted).

Every condition records the same excitation trajectories and real-world seeds, so the rows pair.
The truth columns are the logs' own draws (mean over the logs and joints), read from the recordings'
metadata: this is a benchmark with a known answer, not a blind diagnosis.

Prints its lines, or one JSON object with ``--json`` (its ``"text"`` the lines); progress goes to
stderr. Usage: ``python benchmarks/sysid_latency_bias.py [--seed 100] [--json]`` (about 8 min on
2 cores); ``python -m tools.results save benchlatency -- python benchmarks/sysid_latency_bias.py``
saves it under ``docs/results/``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

DELAY_S = 0.015
#: condition -> effects of the "real" profile recorded beside the fixed delay (None: every effect)
CONDITIONS = {"delay only": (), "+ kp spread": ("kp_scale",), "+ kd spread": ("kd_scale",),
              "+ backlash": ("backlash_rad",), "+ Coulomb friction": ("coulomb_friction_nm",),
              "+ viscous friction": ("viscous_damping",), "+ torque limit": ("torque_limit_scale",),
              "whole real profile": None}


def profile_for(effects) -> dict:
    """The profile of a condition as a dict (``envs.effects.get_profile`` takes it): the delay fixed
    at :data:`DELAY_S`, ``effects`` at the ``"real"`` profile's ranges (None: all of them, on flat
    ground), every other effect at its identity."""
    from envs.effects import EFFECTS, PROFILES

    real = PROFILES["real"]
    names = [f for f in EFFECTS if f not in ("latency_s", "terrain_amplitude")] if effects is None else list(effects)
    return {"name": "latency-bias", "latency_s": [DELAY_S, DELAY_S], **{f: list(getattr(real, f)) for f in names}}


def truth(logs) -> dict:
    """Mean over the logs (and joints) of the draws the real world made for them."""
    keys = ("latency_s", "kp_scale", "coulomb_friction_nm", "viscous_damping")
    vals = {k: [float(np.mean(lg.meta["effects"][k])) for lg in logs] for k in keys}
    return {k: float(np.mean(v)) for k, v in vals.items()}


def run_condition(name: str, effects, seed: int, work: str, calibration: dict) -> dict:
    from experiments.runtime.identify import USE_GROUND_TRUTH, record_excitation_task
    from sysid.candidates import Term
    from sysid.data import load_logs
    from sysid.diagnose import fit_terms

    out = os.path.join(work, name.replace(" ", "_").replace("+", "p"))
    paths = record_excitation_task({"out_dir": out, "fixed_base": True, "profile": profile_for(effects), "n_logs": 3,
                                    "seconds": 6.0, "seed": seed, "lumpy": False})
    logs = load_logs(paths, use_ground_truth=USE_GROUND_TRUTH)
    lat, kp = Term("latency"), Term("pd_gain_all")
    dry, visc = Term("coulomb_friction_all"), Term("viscous_damping_all")
    row = {"condition": name, "truth": truth(logs)}
    for label, start in (("latency", {lat: 0.010}), ("+ kp", {lat: 0.010, kp: 0.95}),
                         ("+ kp + friction", {lat: 0.010, kp: 0.95, dry: 0.02, visc: 0.005})):
        fit = fit_terms(logs, start, calibration=calibration, use_ground_truth=USE_GROUND_TRUTH)
        row[label] = {**{t.label(): float(v) for t, v in fit["values"].items()},
                      "heldout_cost_before": fit["heldout_cost_before"], "heldout_cost_after": fit["heldout_cost_after"]}
    return row


def format_rows(rows: list[dict]) -> list[str]:
    lines = [f"{'condition (15 ms delay +)':<22} {'true kp':>7} {'latency alone':>14} {'+ kp: latency':>14} {'kp':>6}"
             f" {'+ kp + friction: latency':>25} {'kp':>6} {'dry N m':>8} {'visc N m s':>10}"
             f" {'true dry':>8} {'true visc':>9}  held-out cost (3 fits)"]
    for r in rows:
        a, b, c = r["latency"], r["+ kp"], r["+ kp + friction"]
        lines.append(f"{r['condition']:<22} {r['truth']['kp_scale']:>7.3f} {1000 * a['latency']:>11.1f} ms "
                     f"{1000 * b['latency']:>11.1f} ms {b['pd_gain_all']:>6.3f} {1000 * c['latency']:>22.1f} ms "
                     f"{c['pd_gain_all']:>6.3f} {c['coulomb_friction_all']:>8.3f} {c['viscous_damping_all']:>10.4f} "
                     f"{r['truth']['coulomb_friction_nm']:>8.3f} {r['truth']['viscous_damping']:>9.4f}  "
                     f"{a['heldout_cost_after']:.3g} / {b['heldout_cost_after']:.3g} / {c['heldout_cost_after']:.3g}")
    return lines


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=100, help="seed of the excitation trajectories and draws (default 100)")
    ap.add_argument("--json", action="store_true", help="print one JSON object (its \"text\": the lines)")
    args = ap.parse_args(argv)
    from experiments.runtime.executors import limit_blas_threads
    from experiments.runtime.identify import ENGINE_GAP_DIR

    limit_blas_threads()
    with open(ENGINE_GAP_DIR / "fixed.json") as f:
        cal = json.load(f)["calibration"]
    rows, t0 = [], time.perf_counter()
    with tempfile.TemporaryDirectory() as work:
        for name, effects in CONDITIONS.items():
            rows.append(run_condition(name, effects, args.seed, work, cal))
            print(f"[{time.perf_counter() - t0:5.0f} s] {format_rows(rows)[-1]}", file=sys.stderr, flush=True)
    lines = [f"in-air logs: 3 x 6 s per condition, seed {args.seed}; the delay is {1000 * DELAY_S:.0f} ms in every condition",
             *format_rows(rows)]
    out = {"seed": args.seed, "delay_s": DELAY_S, "rows": rows, "text": "\n".join(lines)}
    print(json.dumps(out) if args.json else out["text"], flush=True)
    return out


if __name__ == "__main__":
    main()
