"""Walk-engine benchmark: cost of ``WalkEngine.step`` and of a walking sim rollout.

Run: ``PYTHONPATH=. python benchmarks/bench_walk.py [--episodes 5] [--json out.json] [--save benchwalk]``
(``--save NAME`` also writes ``docs/results/NAME.json`` for the README: these figures, the printed
JSON and the load average).

Reports
* ``step_us_median`` / ``step_us_p90``: one ``WalkEngine.step`` [µs] (target ≤ 100 µs median),
  measured on a walking θ0 plan with a constant observation;
* ``rollouts_per_s``: 7.5 s walking episodes per second in the MuJoCo sim (one process);
* ``bare_mj_step_s``: the same number of physics steps (7500 at 1 kHz) with ``mujoco.mj_step``
  alone, and ``rollout_over_bare``, the ratio of a full walking rollout (engine + env wrapper +
  recording) to that bare stepping.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time

import numpy as np
from common.files import atomic_write_text


def bench_step(n: int = 3000) -> dict:
    from robots import nao_h25
    from walk_engine import WalkEngine, observation_slices

    robot = nao_h25()
    sl = observation_slices(robot)
    obs = np.zeros(sl["size"])
    obs[sl["q"]] = robot.pose("crouch")
    eng = WalkEngine(robot)
    eng.reset(obs)
    for _ in range(100):
        eng.step(obs)
    ts = np.empty(n)
    for i in range(n):
        t = time.perf_counter()
        eng.step(obs)
        ts[i] = time.perf_counter() - t
    return {"step_us_median": float(np.median(ts) * 1e6), "step_us_p90": float(np.percentile(ts, 90) * 1e6)}


def bench_rollouts(episodes: int = 5, seconds: float = 7.5) -> dict:
    import mujoco

    from envs import NaoSimEnv
    from experiments.runtime.fitness import run_walk

    env = NaoSimEnv()
    walls, speeds = [], []
    for s in range(episodes):
        t = time.perf_counter()
        _, res = run_walk(env=env, seed=s, seconds=seconds)
        walls.append(time.perf_counter() - t)
        speeds.append(res.speed_cm_s)
    n_phys = int(round(seconds / env.physics_dt))
    env.reset(seed=0)
    env.data.ctrl[:] = env.q0
    t = time.perf_counter()
    mujoco.mj_step(env.model, env.data, nstep=n_phys)
    bare = time.perf_counter() - t
    wall = float(np.median(walls))
    return {"episode_s": seconds, "rollout_wall_s_median": wall, "rollouts_per_s": 1.0 / wall,
            "bare_mj_step_s": bare, "physics_steps": n_phys, "rollout_over_bare": wall / bare,
            "speed_cm_s": float(np.mean(speeds))}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--episodes", type=int, default=5)
    ap.add_argument("--json", metavar="PATH", help="also write the result to PATH")
    ap.add_argument("--save", metavar="NAME", help="also write docs/results/NAME.json (for the README)")
    args = ap.parse_args(argv)
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    res = {"machine": platform.processor() or platform.machine(), "cpus": os.cpu_count(),
           "load_avg_1min": os.getloadavg()[0], **bench_step(), **bench_rollouts(args.episodes)}
    text = json.dumps(res, indent=2)
    print(text)
    if args.json:
        atomic_write_text(args.json, text)
    if args.save:
        from tools.readme import save_benchmark

        save_benchmark(args.save, "benchmarks/bench_walk.py", sys.argv[1:] if argv is None else list(argv),
                       {**res, "text": text}, res["load_avg_1min"])
    return res


if __name__ == "__main__":
    main()
