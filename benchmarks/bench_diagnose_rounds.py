"""What a diagnosis's second screen/refit round costs and what it finds, side by side in one run.

The identified and hybrid worlds identify the real world from 3 fixed-base (in-air) and 3 stepping
excitation logs (``experiments.runtime.identify.identify_real``), in ``--identify-rounds`` screen/refit
rounds per diagnosis (default 2, ``experiments.runtime.grounding.IDENTIFY_ROUNDS``). This records one such
set of logs of the real world (seed ``--seed``, the shipped engine-gap calibration) and diagnoses
the very same logs with 1 and with 2 rounds, ``--repeats`` times interleaved, under ``cProfile``.
Per number of rounds (medians over the repeats): the wall time of the in-air and the stepping
diagnosis (each report's ``runtime_s``), the share of the whole spent inside MuJoCo's threaded
``rollout`` (``mujoco.rollout``: the physics), the terms each stage kept and the fitted actuation
latency (the real world's lies in 10-20 ms per episode, ``envs.effects``). Diagnoses are
deterministic: every repeat finds the same terms, so the repeats time only.

Prints a table or, with ``--json``, one JSON object; ``--save NAME`` also writes
``docs/results/NAME.json`` for the README (with the load average).

Usage: ``python benchmarks/bench_diagnose_rounds.py [--seed 0] [--repeats 1] [--save benchdiagnose-rounds]``
"""

from __future__ import annotations

import argparse
import cProfile
import json
import os
import pstats
import shutil
import statistics
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

os.environ.setdefault("OMP_NUM_THREADS", "1")


def rollout_seconds(prof: cProfile.Profile) -> float:
    """Seconds a profile spent inside MuJoCo's ``rollout`` (the built-in of ``mujoco._rollout``)."""
    st = pstats.Stats(prof)
    return sum(v[3] for k, v in st.stats.items() if k[2] == "<built-in method mujoco._rollout.rollout>")


def diagnose_once(logs_dir: str, out_dir: str, rounds: int, seed: int, calibration: dict) -> dict:
    """Diagnose the logs recorded in ``logs_dir`` again in ``out_dir`` (a copy of the logs, no
    reports) with ``rounds`` rounds: wall time per stage, rollout share, terms and latency."""
    from experiments.runtime.grounding import IDENTIFY_BUDGET_S
    from experiments.runtime.identify import identify_real

    shutil.rmtree(out_dir, ignore_errors=True)
    for stage in ("fixed", "floating"):
        shutil.copytree(os.path.join(logs_dir, stage, "logs"), os.path.join(out_dir, stage, "logs"))
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.enable()
    res = identify_real(out_dir, seed=seed, calibration=calibration, time_budget_s=IDENTIFY_BUDGET_S, rounds=rounds)
    prof.disable()
    wall = time.perf_counter() - t0
    stages = {}
    for path in res["reports"]:
        with open(path) as f:
            rep = json.load(f)
        stages[os.path.basename(os.path.dirname(path))] = {"runtime_s": rep["runtime_s"], "terms": sorted(rep["model"]),
                                                           "rounds_run": len(rep["rounds"])}
    return {"wall_s": wall, "rollout_share": rollout_seconds(prof) / wall, "stages": stages,
            "latency_ms": 1000 * res["effects"].get("latency", 0.0), "terms": len(res["effects"]),
            "budget_reached": res["time_budget_reached"]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=0, help="seed of the excitation logs and of the real world's draws (default 0)")
    ap.add_argument("--repeats", type=int, default=1, help="interleaved repeats per number of rounds (default 1)")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    ap.add_argument("--save", metavar="NAME", help="also write docs/results/NAME.json")
    args = ap.parse_args(argv)
    if args.repeats < 1 or args.seed < 0:
        ap.error("--repeats must be >= 1 and --seed >= 0")
    from experiments.runtime.identify import (ENGINE_GAP_SEED, calibrate_engines, excitation_tasks,
                                      record_excitation_task)

    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="bench_diagnose_") as tmp:
        cal = calibrate_engines(os.path.join(tmp, "calibration"), seed=ENGINE_GAP_SEED)
        logs = os.path.join(tmp, "logs")
        print(f"[bench_diagnose_rounds] recording 3 in-air and 3 stepping excitation logs (seed {args.seed})",
              file=sys.stderr, flush=True)
        for task in excitation_tasks(logs, seed=args.seed):
            record_excitation_task(task)
        runs: dict[int, list[dict]] = {1: [], 2: []}
        for r in range(args.repeats):
            for rounds in (1, 2):
                runs[rounds].append(diagnose_once(logs, os.path.join(tmp, f"r{rounds}"), rounds, args.seed, cal))
                print(f"[bench_diagnose_rounds] repeat {r + 1}/{args.repeats}, {rounds} round(s): "
                      f"{runs[rounds][-1]['wall_s']:.0f} s", file=sys.stderr, flush=True)
    med = statistics.median
    out = {"seed": args.seed, "repeats": args.repeats, "cpus": os.cpu_count(), "rounds": {}}
    for rounds, rs in runs.items():
        first = rs[0]
        out["rounds"][str(rounds)] = {
            "wall_s": med([x["wall_s"] for x in rs]),
            "fixed_s": med([x["stages"]["fixed"]["runtime_s"] for x in rs]),
            "floating_s": med([x["stages"]["floating"]["runtime_s"] for x in rs]),
            "rollout_share": med([x["rollout_share"] for x in rs]),
            "latency_ms": first["latency_ms"], "terms": first["terms"],
            "fixed_terms": first["stages"]["fixed"]["terms"], "floating_terms": first["stages"]["floating"]["terms"],
            "rounds_run": {k: v["rounds_run"] for k, v in first["stages"].items()},
            "same_every_repeat": all(x["stages"][k]["terms"] == first["stages"][k]["terms"] for x in rs for k in first["stages"]),
            "budget_reached": sorted({b for x in rs for b in x["budget_reached"]})}
    one, two = out["rounds"]["1"], out["rounds"]["2"]
    out["ratio_wall_two_vs_one"] = two["wall_s"] / one["wall_s"]
    out["ratio_fixed_two_vs_one"] = two["fixed_s"] / one["fixed_s"]
    rows = [f"seed {args.seed}, 3 in-air + 3 stepping logs of 6 s, medians of {args.repeats} interleaved repeat(s), "
            f"{os.cpu_count()} cores",
            f"{'rounds':>6s} {'in-air s':>9s} {'stepping s':>11s} {'total s':>8s} {'in rollout':>11s} {'terms':>6s} "
            f"{'latency ms':>11s}  in-air terms"]
    for k, v in out["rounds"].items():
        rows.append(f"{k:>6s} {v['fixed_s']:9.1f} {v['floating_s']:11.1f} {v['wall_s']:8.1f} "
                    f"{100 * v['rollout_share']:10.0f}% {v['terms']:6d} {v['latency_ms']:11.1f}  {', '.join(v['fixed_terms'])}")
    rows.append(f"two rounds / one: in-air diagnosis {out['ratio_fixed_two_vs_one']:.2f}x, whole identification "
                f"{out['ratio_wall_two_vs_one']:.2f}x")
    out["text"] = "\n".join(rows)
    from tools.readme import finish_benchmark

    finish_benchmark(out, "benchmarks/bench_diagnose_rounds.py", argv, save_name=args.save, as_json=args.json, load_before=load0)
    return 0


if __name__ == "__main__":
    sys.exit(main())
