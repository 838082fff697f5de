"""Throughput of the two worlds: env.step vs the bare engine on the same model, side by side.

For each world (MuJoCo sim, PyBullet real with the "none" and "real" profiles) on flat ground and
on a 1 cm lumpy heightfield, the robot holds the walking crouch and we time

* ``env.step``: one 100 Hz control step (10 physics steps at 1 kHz, PD, sensors, fall check);
* the bare engine doing the same physics: ``mujoco.mj_step(model, data, nstep=10)`` with the
  actuators holding the pose, or 10 x ``stepSimulation`` (no PD: the state is restored from a
  snapshot every 20 control steps so contacts stay like standing).

Runs are interleaved and repeated; the table gives medians (control steps per second) and the
ratio env/bare (1.0 = no overhead). ``--save NAME`` also writes ``docs/results/NAME.json`` for the
README (medians, ratios, the printed table, the load average).
Usage: ``python benchmarks/bench_envs.py [--repeats 5] [--steps 300] [--save benchenvs]``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import mujoco

from envs import NaoRealEnv, NaoSimEnv
from terrain import lumpy


def time_env(env, steps):
    a = env.robot.pose("crouch", actuated=True)
    env.reset(seed=0)
    t = time.perf_counter()
    for _ in range(steps):
        env.step(a)
    return steps / (time.perf_counter() - t)


def time_bare_mujoco(env, steps):
    env.reset(seed=0)
    m, d = env.model, env.data
    t = time.perf_counter()
    for _ in range(steps):
        mujoco.mj_step(m, d, nstep=env.n_substeps)
    return steps / (time.perf_counter() - t)


def time_bare_bullet(env, steps):
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


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--steps", type=int, default=300, help="control steps per timing")
    ap.add_argument("--save", metavar="NAME", help="also write docs/results/NAME.json (for the README)")
    args = ap.parse_args(argv)
    load_before = os.getloadavg()[0]
    hf = lumpy(0, amplitude=0.01)
    cases = {
        "sim  flat": (NaoSimEnv(), time_bare_mujoco),
        "sim  lumpy 1cm": (NaoSimEnv(terrain=hf), time_bare_mujoco),
        "real flat  (none)": (NaoRealEnv(profile="none", terrain="flat"), time_bare_bullet),
        "real lumpy 1cm (none)": (NaoRealEnv(profile="none", terrain=hf), time_bare_bullet),
        "real lumpy (profile real)": (NaoRealEnv(profile="real"), time_bare_bullet),
    }
    res = {k: ([], []) for k in cases}
    for _ in range(args.repeats):
        for k, (env, bare) in cases.items():
            res[k][0].append(time_env(env, args.steps))
            res[k][1].append(bare(env, args.steps))
    lines = [f"median of {args.repeats} interleaved runs, {args.steps} control steps each (100 Hz control, 1 kHz physics)",
             f"{'case':28s} {'env.step/s':>11s} {'bare/s':>9s} {'env/bare':>9s} {'x realtime':>11s}"]
    out = {"repeats": args.repeats, "steps": args.steps, "control_hz": 100, "cases": {}}
    for k, (e, b) in res.items():
        me, mb = statistics.median(e), statistics.median(b)
        lines.append(f"{k:28s} {me:11.0f} {mb:9.0f} {me / mb:9.2f} {me / 100:11.1f}")
        out["cases"][k] = {"env_steps_per_s": me, "bare_steps_per_s": mb, "env_over_bare": me / mb,
                           "x_realtime": me / 100}
    out["text"] = "\n".join(lines)
    print(out["text"])
    if args.save:
        from tools.readme import save_benchmark

        save_benchmark(args.save, "benchmarks/bench_envs.py", sys.argv[1:] if argv is None else list(argv), out,
                       load_before)
    return out


if __name__ == "__main__":
    main()
