"""How long does logging a 7.5 s rollout to Rerun take: columnar (what we ship) against row by row?

A 7.5 s rollout (750 control steps) is made once in the MuJoCo sim (walking with the initial gait
parameters when ``walk_engine`` is available, else holding the crouch), then logged to an ``.rrd``
file repeatedly with :func:`experiments.viz.log_rollouts_to_rrd`, which sends every time-varying
entity with one ``send_columns`` call (25 link transforms, 36 leg-joint series, IMU, feet,
balance series, CoM/CoP/plan markers, footsteps). Two figures per run:

* ``log``: building + sending (what the optimizer waits for), without the final flush to disk;
* ``total``: including the blueprint, the flush and the atomic rename.

For comparison the same time-varying data is logged row by row (``set_time`` + ``log`` per entity
per step, the pattern of most tutorials), and the median columnar time is put against the 7.5 s of
robot time and against the wall time of simulating the rollout (columnar / row by row: above 1,
the columnar way is faster). The target is < 0.3 s.

Prints its lines, or one JSON object with ``--json`` (its ``"text"`` the lines); progress and the
directory of the ``.rrd`` files go to stderr. Defaults (7 columnar runs, 3 of two rollouts, 1 row
by row) take about 10 s on 2 idle cores.

Usage: ``python benchmarks/bench_rerun.py [--repeats 7] [--row-repeats 1] [--out DIR] [--json]``
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def make_rollout(seconds: float = 7.5):
    from envs import make_world
    from envs.rollout import HoldPose, rollout  # not from envs: its lazy `rollout` is shadowed by the submodule once loaded
    from experiments.viz import plan_from_engine

    env = make_world("sim")
    try:
        from walk_engine import GaitParams, WalkEngine

        ctrl, what = WalkEngine(env.robot, GaitParams()), "walking with θ0"
        meta = {"params": GaitParams().to_dict()}
    except ImportError:
        ctrl, what, meta = HoldPose(env.robot), "holding the crouch", {}
    t = time.perf_counter()
    rec = rollout(env, ctrl, seed=0, seconds=seconds, meta=meta)
    sim_wall = time.perf_counter() - t
    if hasattr(ctrl, "diagnostics"):
        rec = plan_from_engine(rec, ctrl.diagnostics())
    env.close()
    return rec, what, sim_wall


def log_rows(rec, path):
    """The time-varying part of experiments.viz, logged with one ``log`` call per entity per step."""
    import rerun as rr

    from experiments.viz import _xyzw, link_poses

    robot = rec.robot
    stream = rr.RecordingStream("sgatwalk-bench", recording_id="rows")
    stream.save(path)
    t0 = time.perf_counter()
    links, pos, quat, _ = link_poses(rec)
    xyzw = _xyzw(quat)
    legs = [robot.joint_names.index(j) for j in robot.groups["legs"]]
    q = rec.group("q")
    cmd = robot.expand_action(rec.group("cmd"))
    app = robot.expand_action(rec.group("app"))
    extra = {f"ts/{g}/{i}": rec.group(g)[:, i] for g in ("gyro", "angle", "fsr") for i in range(rec.group(g).shape[1])}
    com = rec.group("gt.com")
    for k, t in enumerate(rec.t):
        stream.set_time("time", duration=float(t))
        stream.set_time("step", sequence=k)
        for i, link in enumerate(links):
            stream.log(f"/sim/robot/{link}", rr.Transform3D(translation=pos[k, i], quaternion=xyzw[k, i]))
        for j in legs:
            name = robot.joint_names[j]
            for kind, arr in (("cmd", cmd), ("app", app), ("q", q)):
                stream.log(f"/sim/ts/joints/{name}/{kind}", rr.Scalars(arr[k, j]))
        for key, arr in extra.items():
            stream.log(f"/sim/{key}", rr.Scalars(arr[k]))
        for ax in range(2):
            stream.log(f"/sim/ts/balance/{'xy'[ax]}/com", rr.Scalars(com[k, ax]))
        stream.log("/sim/com", rr.Points3D([com[k]]))
    t_log = time.perf_counter() - t0
    stream.flush()
    stream.disconnect()
    return t_log, time.perf_counter() - t0


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 epilog="About 10 s at the defaults on 2 idle cores.")
    ap.add_argument("--repeats", type=int, default=7,
                    help="columnar runs (default 7; half as many, at least 1, of two rollouts side by side)")
    ap.add_argument("--row-repeats", type=int, default=1, help="row-by-row runs (default 1; 0: none; some seconds each)")
    ap.add_argument("--out", default=None, help="keep the .rrd files in this directory (default: a temporary one, removed)")
    ap.add_argument("--json", action="store_true", help="print one JSON object (its \"text\": the lines)")
    args = ap.parse_args(argv)
    if args.repeats < 1 or args.row_repeats < 0:
        ap.error("--repeats must be >= 1 and --row-repeats >= 0")
    lines = []

    def say(line):
        if not args.json:
            print(line, flush=True)
        lines.append(line)

    from experiments.viz import log_rollouts_to_rrd

    rec, what, sim_wall = make_rollout()
    tmp = None if args.out else tempfile.TemporaryDirectory(prefix="bench_rerun_")
    out = args.out or tmp.name
    os.makedirs(out, exist_ok=True)
    say(f"rollout: {len(rec)} rows = {rec.t[-1] + rec.meta['control_dt']:.2f} s of robot time ({what}); "
        f"simulating it took {sim_wall:.2f} s")

    log_rollouts_to_rrd({"sim": rec}, os.path.join(out, "warmup.rrd"))  # imports, first-call costs
    logs, totals, size = [], [], 0
    for _ in range(args.repeats):
        r = log_rollouts_to_rrd({"sim": rec}, os.path.join(out, "columnar.rrd"))
        logs.append(r["log_seconds"])
        totals.append(r["seconds"])
        size = r["bytes"]
    n_ent = len(r["rows"])
    med_log, med_tot = statistics.median(logs), statistics.median(totals)
    say(f"columnar (send_columns, {n_ent} time-varying entities, one call each): median log {med_log * 1e3:.0f} ms, "
        f"total {med_tot * 1e3:.0f} ms (min {min(totals) * 1e3:.0f}, max {max(totals) * 1e3:.0f}, n={len(totals)}); "
        f"{size / 1e6:.2f} MB")

    pair = []
    for _ in range(max(1, args.repeats // 2)):
        pair.append(log_rollouts_to_rrd({"sim": rec, "sim2": rec}, os.path.join(out, "two.rrd"))["seconds"])
    say(f"two rollouts side by side: median total {statistics.median(pair) * 1e3:.0f} ms")

    robot_time = float(rec.t[-1] + rec.meta["control_dt"])
    result = {"rows": len(rec), "robot_time_s": robot_time, "controller": what, "sim_wall_s": sim_wall,
              "repeats": args.repeats, "row_repeats": args.row_repeats, "entities": n_ent, "bytes": size,
              "columnar_log_s_median": med_log, "columnar_total_s_median": med_tot,
              "columnar_total_s_min": min(totals), "columnar_total_s_max": max(totals),
              "two_rollouts_total_s_median": statistics.median(pair)}
    rows_log, rows_tot = [], []
    for _ in range(args.row_repeats):
        a, b = log_rows(rec, os.path.join(out, "rows.rrd"))
        rows_log.append(a)
        rows_tot.append(b)
    if rows_tot:
        rl, rt = statistics.median(rows_log), statistics.median(rows_tot)
        say(f"row by row (set_time + log per entity per step, same time-varying data without the statics): "
            f"log {rl:.2f} s, total {rt:.2f} s -> columnar is {rt / med_tot:.0f}x faster")
        result.update(rows_log_s_median=rl, rows_total_s_median=rt, rows_over_columnar=rt / med_tot)
    say(f"columnar total = {100 * med_tot / robot_time:.1f} % of the robot time, "
        f"{100 * med_tot / sim_wall:.0f} % of the simulation wall time; target < 0.3 s: "
        f"{'met' if med_tot < 0.3 else 'MISSED'}")
    result.update(target_s=0.3, target_met=med_tot < 0.3, text="\n".join(lines))
    if tmp is None:
        print(f"[bench_rerun] files in {out}", file=sys.stderr, flush=True)
    else:
        tmp.cleanup()
    if args.json:
        print(json.dumps(result), flush=True)
    return result


if __name__ == "__main__":
    main()
