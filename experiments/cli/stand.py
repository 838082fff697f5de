"""``sgatwalk stand``: hold the walking crouch in the sim and/or the real world and report.

The demo of the two worlds: the robot stands in a pose for ``--seconds`` on flat ground or on a
heightfield; the command prints, per world, whether it fell, how far its CoM drifted, the mean
foot forces and the simulation speed, and can write each rollout as a Parquet recording.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from terrain import TERRAINS, check_amplitude, make
import experiments.cli.argtypes as A


def register(sub) -> argparse.ArgumentParser:
    p = sub.add_parser("stand", help="hold a pose in the sim and/or real world (demo of the two worlds)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--world", default="sim,real", help="sim, real or sim,real (default: both)")
    p.add_argument("--pose", default="crouch", help="robot pose to hold (zero, stand, crouch; the NAO also deep_crouch)")
    p.add_argument("--seconds", type=A.seconds, default=10.0, help="duration [s] (default 10)")
    p.add_argument("--seed", type=A.seed, default=0, help="episode seed (terrain, effects, noise)")
    p.add_argument("--profile", default="real", help="real-world effect profile: real (default), none, real-flat (real on flat ground) or real-ground (its uneven ground alone)")
    p.add_argument("--terrain", default=None, choices=TERRAINS,
                   help="terrain for both worlds (default: flat sim, the profile's random lumpy field in real)")
    p.add_argument("--amplitude", type=A.real(0.0, 1.0), default=None,
                   help="terrain amplitude with --terrain: bump/step height [m], slope grade, gaussian RMS height [m] "
                        "(default 0.01)")
    p.add_argument("--fixed-base", action="store_true", help="hang the robot in the air (actuator tests)")
    A.add_robot(p)
    p.add_argument("--record", type=A.out_file, metavar="PATH", help="write recordings; '{world}' in PATH is replaced "
                   "(default PATH for two worlds: PATH with _sim/_real before the suffix)")
    return p


def _record_path(path: str, world: str, n_worlds: int) -> str:
    if "{world}" in path:
        return path.format(world=world)
    if n_worlds == 1:
        return path
    root, ext = os.path.splitext(path)
    return f"{root}_{world}{ext or '.parquet'}"


def run(args) -> dict:
    from envs import HoldPose, make_world, rollout  # lazy: engines load only when the command runs
    from robots import get_robot  # lazy: g1/talos parse their URDFs

    robot = get_robot(args.robot)
    robot.pose(args.pose)  # KeyError naming the known poses, before any world is built

    worlds = [w.strip() for w in args.world.split(",") if w.strip()]
    for w in worlds:
        if w not in ("sim", "real"):
            raise ValueError(f"unknown world {w!r}; choose from sim, real")
    hf = None
    if args.amplitude is not None and args.terrain is None:
        raise ValueError("--amplitude needs --terrain (e.g. --terrain lumpy --amplitude 0.01)")
    if args.terrain is not None:
        amp = check_amplitude(args.terrain, 0.01 if args.amplitude is None else args.amplitude)
        hf = make(args.terrain, seed=args.seed, amplitude=amp)
    results = []
    for w in worlds:
        kw = {"fixed_base": args.fixed_base, "robot": robot}
        if w == "real":
            kw.update(profile=args.profile, terrain=hf if hf is not None else "lumpy")
        else:
            kw.update(terrain=hf)
        env = make_world(w, **kw)
        ctrl = HoldPose(env.robot, args.pose)
        t0 = time.perf_counter()
        rec = rollout(env, ctrl, seed=args.seed, seconds=args.seconds)
        wall = time.perf_counter() - t0
        com = rec.group("gt.com")
        fsr = rec.group("fsr")
        res = {
            "world": w, "fell": rec.fell, "fall_reason": rec.meta["fall_reason"], "fall_time_s": rec.meta["fall_time"],
            "seconds": float(len(rec) * env.control_dt),
            "com_drift_m": float(np.linalg.norm(com[-1, :2] - com[0, :2])),
            "com_height_m": float(com[-1, 2]),
            "foot_force_n": [float(v) for v in fsr[len(fsr) // 2:].mean(0)],
            "terrain": rec.meta["terrain"]["name"] if rec.meta["terrain"] else "flat",
            "wall_s": wall, "realtime_factor": float(len(rec) * env.control_dt / wall),
        }
        if w == "real":
            res["profile"] = env.profile.name
        if args.record:
            res["recording"] = rec.to_parquet(_record_path(args.record, w, len(worlds)))
        results.append(res)
        env.close()
    if not args.json:
        print(format_stand(results))
    return {"robot": args.robot, "pose": args.pose, "seed": args.seed, "worlds": results}


def format_stand(results: list[dict]) -> str:
    """The table ``sgatwalk stand`` prints, from its per-world results (also from ``--json``; the
    real-time factor shows when the result has it, i.e. with ``--timings``)."""
    rt = all("realtime_factor" in r for r in results)
    lines = [f"{'world':6s} {'fell':5s} {'reason':10s} {'CoM drift':>10s} {'CoM z':>7s} {'feet L/R [N]':>14s} "
             f"{'terrain':22s}" + (f" {'x realtime':>10s}" if rt else "")]
    for r in results:
        lines.append(f"{r['world']:6s} {str(r['fell']):5s} {str(r['fall_reason'] or '-'):10s} "
                     f"{1000 * r['com_drift_m']:8.1f}mm {r['com_height_m']:7.3f} "
                     f"{r['foot_force_n'][0]:6.1f}/{r['foot_force_n'][1]:6.1f} {r['terrain']:22s}"
                     + (f" {r['realtime_factor']:10.1f}" if rt else "")
                     + (f"  -> {r['recording']}" if "recording" in r else ""))
    return "\n".join(lines)
