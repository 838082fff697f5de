"""What does the uneven-ground fit's adaptive RMS-height grid save against the whole grid, and does it
identify exactly the same? Both side by side in one run.

The stepping diagnosis fits terrain roughness by simulating every stepping log on random surfaces
of each RMS height of a grid (``sysid.roughness.RMS_HEIGHTS``) and replaying the simulated logs:
the largest part of an identification (``experiments.runtime.identify.identify_real``). The grid is
simulated bottom-up, only as far as the fit needs it (``fit_roughness(adaptive=True)``). This
records one set of excitation logs of the real world per seed (3 in-air, 3 stepping; the shipped
engine-gap calibration) and identifies the very same logs twice per repeat, interleaved: with the
whole grid (``adaptive=False``, patched in for this run) and with the adaptive one. Per seed: wall
time of the whole identification and of the stepping diagnosis (medians over the repeats), the RMS
heights simulated, the fitted height and its interval, and whether the two identifications agree
exactly (every identified effect's value, the roughness fit's decision, height and interval: they
must); over the seeds, the medians of the ratios whole / adaptive.

Prints a table or, with ``--json``, one JSON object (its ``"text"`` the table); progress goes to
stderr. Exits 1 unless every identification agrees. The default (seed 0, 1 repeat) takes about
4 minutes on 2 idle cores (2 more where the shipped engine-gap calibration is stale and is computed
afresh); each further seed or repeat adds about as much (``--seeds 0 1 2``: about 12 minutes).

Usage: ``python benchmarks/bench_roughness_grid.py [--seeds 0] [--repeats 1] [--json]``
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import shutil
import statistics
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

os.environ.setdefault("OMP_NUM_THREADS", "1")

#: The roughness fit's fields that must not depend on how much of the grid was simulated.
FIT_FIELDS = ("rms_height", "ci95", "declared", "reason", "peak_height", "excess_obs", "heldout_p", "sim_log_excess",
              "profile_cosine", "profile_pred", "excess_heldout_pred", "excess_heldout_left")


def identify_once(logs_dir: str, out_dir: str, seed: int, calibration: dict, adaptive: bool) -> dict:
    """Identify the logs recorded in ``logs_dir`` again in ``out_dir`` (a copy of the logs) with the
    adaptive or the whole RMS-height grid: wall time, the stepping report's runtime and roughness fit,
    and the identified effects."""
    import sysid.roughness as roughness
    from experiments.runtime.grounding import IDENTIFY_BUDGET_S, IDENTIFY_ROUNDS
    from experiments.runtime.identify import identify_real

    shutil.rmtree(out_dir, ignore_errors=True)
    for stage in ("fixed", "floating"):
        shutil.copytree(os.path.join(logs_dir, stage, "logs"), os.path.join(out_dir, stage, "logs"))
    fit = roughness.fit_roughness
    # the diagnosis imports fit_roughness from the module when it gets to the ground: patch it there
    roughness.fit_roughness = functools.partial(fit, adaptive=adaptive)
    try:
        t0 = time.perf_counter()
        res = identify_real(out_dir, seed=seed, calibration=calibration, time_budget_s=IDENTIFY_BUDGET_S,
                            rounds=IDENTIFY_ROUNDS)
        wall = time.perf_counter() - t0
    finally:
        roughness.fit_roughness = fit
    with open(os.path.join(out_dir, "floating", "report.json")) as f:
        rep = json.load(f)
    rough = rep["terrain_roughness"] or {}
    return {"wall_s": wall, "stepping_s": rep["runtime_s"], "effects": res["effects"],
            "terrain_rms_height": res["terrain_rms_height"], "grid_mm": [1000 * g for g in rough.get("grid", [])],
            "fit": {k: rough.get(k) for k in FIT_FIELDS}, "budget_reached": res["time_budget_reached"]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 epilog="About 4 minutes at the defaults on 2 idle cores, as much again per further "
                                        "seed or repeat. Exits 1 unless the two grids identify the same.")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0],
                    help="seeds of the excitation logs and of the real world's draws (default 0)")
    ap.add_argument("--repeats", type=int, default=1, help="interleaved repeats per seed and grid (default 1)")
    ap.add_argument("--json", action="store_true", help="print one JSON object (its \"text\": the table)")
    args = ap.parse_args(argv)
    if args.repeats < 1 or min(args.seeds) < 0:
        ap.error("--repeats must be >= 1 and every seed >= 0")
    from experiments.runtime.identify import ENGINE_GAP_SEED, calibrate_engines, excitation_tasks, record_excitation_task
    from sysid.roughness import RMS_HEIGHTS
    from experiments.runtime.executors import limit_blas_threads

    # one BLAS thread, also where numpy was loaded before this module set OMP_NUM_THREADS (a runner, a
    # test): with numpy's own two threads the two grids' identifications were seen to differ
    limit_blas_threads()

    med = statistics.median
    out = {"seeds": {}, "repeats": args.repeats, "cpus": os.cpu_count(), "grid_mm": [1000 * g for g in RMS_HEIGHTS]}
    with tempfile.TemporaryDirectory(prefix="bench_roughness_") as tmp:
        cal = calibrate_engines(os.path.join(tmp, "calibration"), seed=ENGINE_GAP_SEED)
        for seed in args.seeds:
            logs = os.path.join(tmp, f"logs{seed}")
            print(f"[bench_roughness_grid] seed {seed}: recording 3 in-air and 3 stepping excitation logs",
                  file=sys.stderr, flush=True)
            for task in excitation_tasks(logs, seed=seed):
                record_excitation_task(task)
            runs: dict[str, list[dict]] = {"whole": [], "adaptive": []}
            for r in range(args.repeats):
                for name in runs:
                    runs[name].append(identify_once(logs, os.path.join(tmp, name), seed, cal, name == "adaptive"))
                    print(f"[bench_roughness_grid] seed {seed}, repeat {r + 1}/{args.repeats}, {name} grid: "
                          f"{runs[name][-1]['wall_s']:.0f} s", file=sys.stderr, flush=True)
            w, a = runs["whole"][0], runs["adaptive"][0]
            out["seeds"][str(seed)] = {
                name: {"wall_s": med([x["wall_s"] for x in rs]), "stepping_s": med([x["stepping_s"] for x in rs]),
                       "grid_mm": rs[0]["grid_mm"], "rms_height_mm": 1000 * rs[0]["terrain_rms_height"],
                       "ci95_mm": [1000 * v for v in rs[0]["fit"]["ci95"]] if rs[0]["fit"]["ci95"] else None,
                       "declared": rs[0]["fit"]["declared"],
                       "budget_reached": sorted({b for x in rs for b in x["budget_reached"]})}
                for name, rs in runs.items()}
            out["seeds"][str(seed)]["identical"] = all(
                x["effects"] == w["effects"] and x["fit"] == w["fit"] and x["terrain_rms_height"] == w["terrain_rms_height"]
                for x in runs["whole"] + runs["adaptive"])
            out["seeds"][str(seed)]["first_differences"] = sorted(
                k for k in set(w["fit"]) | {"effects"}
                if (w["effects"] != a["effects"] if k == "effects" else w["fit"][k] != a["fit"][k]))
    per = out["seeds"].values()
    out["ratio_wall_whole_vs_adaptive"] = med([s["whole"]["wall_s"] / s["adaptive"]["wall_s"] for s in per])
    out["ratio_stepping_whole_vs_adaptive"] = med([s["whole"]["stepping_s"] / s["adaptive"]["stepping_s"] for s in per])
    out["saved_s_median"] = med([s["whole"]["wall_s"] - s["adaptive"]["wall_s"] for s in per])
    out["all_identical"] = all(s["identical"] for s in per)
    rows = [f"{len(out['seeds'])} seed(s), 3 in-air + 3 stepping logs of 6 s each, medians of {args.repeats} interleaved "
            f"repeat(s), {os.cpu_count()} cores; grid {', '.join(f'{g:g}' for g in out['grid_mm'])} mm",
            f"{'seed':>4s} {'grid':>9s} {'identify s':>11s} {'stepping s':>11s}  {'Sq mm [95 % CI]':<22s} heights simulated [mm]"]
    for seed, s in out["seeds"].items():
        for name in ("whole", "adaptive"):
            v = s[name]
            ci = f"[{v['ci95_mm'][0]:.2f}, {v['ci95_mm'][1]:.2f}]" if v["ci95_mm"] else ""
            rows.append(f"{seed:>4s} {name:>9s} {v['wall_s']:11.1f} {v['stepping_s']:11.1f}  "
                        f"{v['rms_height_mm']:.2f} {ci:<17s} {', '.join(f'{g:g}' for g in v['grid_mm'][1:])}")
        rows.append(f"{'':>4s} {'':>9s} identical identification: {'yes' if s['identical'] else 'NO: ' + ', '.join(s['first_differences'])}")
    rows.append(f"whole grid / adaptive (median over seeds): identification {out['ratio_wall_whole_vs_adaptive']:.2f}x "
                f"(median {out['saved_s_median']:.0f} s saved), stepping diagnosis {out['ratio_stepping_whole_vs_adaptive']:.2f}x")
    out["text"] = "\n".join(rows)
    print(json.dumps(out) if args.json else out["text"], flush=True)
    return 0 if out["all_identical"] else 1


if __name__ == "__main__":
    sys.exit(main())
