"""How much does each world's ``env.step`` cost beyond the bare physics engine under it?

Per world (the MuJoCo sim, ``envs.SimWorld``; the PyBullet real world, ``envs.RealWorld``, with the
``none`` and the ``real`` effect profiles) on flat ground and on a 1 cm lumpy heightfield, the robot
holds the walking crouch, and side by side in one run:

* ``env.step``: one 100 Hz control step (10 physics steps at 1 kHz, PD, sensors, fall check);
* the bare engine doing the same physics: ``mujoco.mj_step(model, data, nstep=10)`` with the
  actuators holding the pose, or 10 x ``stepSimulation`` (no PD: the state is restored from a
  snapshot every 20 control steps so contacts stay like standing).

Cases are interleaved and repeated ``--repeats`` times; the table gives the medians (control steps
per second), the ratio env/bare (1.0 = no overhead) and the real-time factor. Prints the table, or
one JSON object with ``--json`` (its ``"text"`` the table); progress goes to stderr.

Defaults (5 repeats of 300 control steps per case and way) take about 30 s on 2 idle cores.

Usage: ``python benchmarks/bench_envs.py [--repeats 5] [--steps 300] [--json]``
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import mujoco  # noqa: E402

from envs import RealWorld, SimWorld  # noqa: E402
from terrain import lumpy  # noqa: E402


def time_env(env, steps):
    """Control steps per second of ``env.step`` holding the crouch."""
    a = env.robot.pose("crouch", actuated=True)
    env.reset(seed=0)
    t = time.perf_counter()
    for _ in range(steps):
        env.step(a)
    return steps / (time.perf_counter() - t)


def time_bare_mujoco(env, steps):
    """Control steps per second of bare ``mj_step`` (10 physics steps each) on the env's model."""
    env.reset(seed=0)
    m, d = env.model, env.data
    t = time.perf_counter()
    for _ in range(steps):
        mujoco.mj_step(m, d, nstep=env.n_substeps)
    return steps / (time.perf_counter() - t)


def time_bare_bullet(env, steps):
    """Control steps per second of bare ``stepSimulation`` (10 each) on the env's client, the state
    restored from a snapshot every 20 control steps."""
    env.reset(seed=0)
    p = env.client
    snap = p.saveState()
    elapsed = 0.0
    for k in range(steps):
        if k % 20 == 0:
            p.restoreState(snap)
        t = time.perf_counter()
        for _ in range(env.n_substeps):
            p.stepSimulation()
        elapsed += time.perf_counter() - t
    return steps / elapsed


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 epilog="About 30 s at the defaults on 2 idle cores.")
    ap.add_argument("--repeats", type=int, default=5, help="interleaved repeats of every case (default 5)")
    ap.add_argument("--steps", type=int, default=300, help="control steps per timing (default 300)")
    ap.add_argument("--json", action="store_true", help="print one JSON object (its \"text\": the table)")
    args = ap.parse_args(argv)
    if args.repeats < 1 or args.steps < 1:
        ap.error("--repeats and --steps must be >= 1")
    hf = lumpy(0, amplitude=0.01)
    cases = {
        "sim  flat": (SimWorld(), time_bare_mujoco),
        "sim  lumpy 1cm": (SimWorld(terrain=hf), time_bare_mujoco),
        "real flat  (none)": (RealWorld(profile="none", terrain="flat"), time_bare_bullet),
        "real lumpy 1cm (none)": (RealWorld(profile="none", terrain=hf), time_bare_bullet),
        "real lumpy (profile real)": (RealWorld(profile="real"), time_bare_bullet),
    }
    res = {k: ([], []) for k in cases}
    for r in range(args.repeats):
        for k, (env, bare) in cases.items():
            res[k][0].append(time_env(env, args.steps))
            res[k][1].append(bare(env, args.steps))
        print(f"[bench_envs] repeat {r + 1}/{args.repeats} done", file=sys.stderr, flush=True)
    for env, _ in cases.values():
        env.close()
    lines = [f"median of {args.repeats} interleaved runs, {args.steps} control steps each (100 Hz control, 1 kHz physics)",
             f"{'case':28s} {'env.step/s':>11s} {'bare/s':>9s} {'env/bare':>9s} {'x realtime':>11s}"]
    out = {"repeats": args.repeats, "steps": args.steps, "control_hz": 100, "cases": {}}
    for k, (e, b) in res.items():
        me, mb = statistics.median(e), statistics.median(b)
        ratio = statistics.median(x / y for x, y in zip(e, b))  # per repeat: both ways timed side by side
        lines.append(f"{k:28s} {me:11.0f} {mb:9.0f} {ratio:9.2f} {me / 100:11.1f}")
        out["cases"][k] = {"env_steps_per_s": me, "bare_steps_per_s": mb, "env_over_bare": ratio, "x_realtime": me / 100}
    lines.append("env/bare: the median over repeats of env.step's rate over the bare engine's (1.0 = no overhead)")
    out["text"] = "\n".join(lines)
    print(json.dumps(out) if args.json else out["text"], flush=True)
    return out


if __name__ == "__main__":
    main()
