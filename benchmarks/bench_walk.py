"""What does the walk engine cost, and how close does a walking sim rollout run to bare ``mj_step``?

Side by side in one run:

* one ``WalkEngine.step`` [µs] (median and 90th percentile of ``--steps`` calls; target <= 100 µs
  median), on a walking θ0 plan with a constant observation;
* ``--episodes`` 7.5 s walks of θ0 in the MuJoCo sim (``envs.SimWorld``, one process: walk engine,
  env, recording), each followed by the same number of physics steps (7500 at 1 kHz) of bare
  ``mujoco.mj_step`` holding the crouch; medians of both and the median ratio rollout / bare
  (1.0 = the physics limit), and walks per second.

Prints a table, or one JSON object with ``--json`` (its ``"text"`` the table); progress goes to
stderr. Defaults (3000 engine steps, 5 walks) take about 10 s on 2 idle cores.

Usage: ``python benchmarks/bench_walk.py [--episodes 5] [--steps 3000] [--json]``
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import numpy as np  # noqa: E402


def bench_step(n: int = 3000) -> dict:
    """Times of ``n`` calls of ``WalkEngine.step`` (after 100 warm-up calls) [µs]."""
    from robots import nao_h25
    from robots.observation import ObservationLayout
    from walk_engine import WalkEngine

    robot = nao_h25()
    layout = ObservationLayout(robot)
    obs = np.zeros(layout.size)
    obs[layout["q"]] = robot.pose("crouch")
    eng = WalkEngine(robot)
    eng.reset(obs)
    for _ in range(100):
        eng.step(obs)
    ts = np.empty(n)
    for i in range(n):
        t = time.perf_counter()
        eng.step(obs)
        ts[i] = time.perf_counter() - t
    return {"step_calls": n, "step_us_median": float(np.median(ts) * 1e6), "step_us_p90": float(np.percentile(ts, 90) * 1e6)}


def bench_rollouts(episodes: int = 5, seconds: float = 7.5) -> dict:
    """``episodes`` walks of θ0 in the sim, each followed by bare ``mj_step`` of the same physics steps."""
    import mujoco

    from envs import SimWorld
    from experiments.runtime.fitness import run_walk

    env = SimWorld()
    n_phys = int(round(seconds / env.physics_dt))
    walls, bares, speeds = [], [], []
    for s in range(episodes):
        t = time.perf_counter()
        _, res = run_walk(env=env, seed=s, seconds=seconds)
        walls.append(time.perf_counter() - t)
        speeds.append(res.speed_cm_s)
        env.reset(seed=0)
        env.data.ctrl[:] = env.q0
        t = time.perf_counter()
        mujoco.mj_step(env.model, env.data, nstep=n_phys)
        bares.append(time.perf_counter() - t)
        print(f"[bench_walk] walk {s + 1}/{episodes}: {walls[-1]:.2f} s, bare {bares[-1]:.2f} s", file=sys.stderr, flush=True)
    env.close()
    wall = statistics.median(walls)
    return {"episodes": episodes, "episode_s": seconds, "rollout_wall_s_median": wall, "rollouts_per_s": 1.0 / wall,
            "bare_mj_step_s_median": statistics.median(bares), "physics_steps": n_phys,
            "rollout_over_bare": statistics.median(w / b for w, b in zip(walls, bares)),
            "speed_cm_s": float(np.mean(speeds))}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 epilog="About 10 s at the defaults on 2 idle cores.")
    ap.add_argument("--episodes", type=int, default=5, help="walks of θ0 (each paired with bare mj_step; default 5)")
    ap.add_argument("--steps", type=int, default=3000, help="timed WalkEngine.step calls (default 3000)")
    ap.add_argument("--seconds", type=float, default=7.5, help="length of a walk [s] (default 7.5, the paper's)")
    ap.add_argument("--json", action="store_true", help="print one JSON object (its \"text\": the table)")
    args = ap.parse_args(argv)
    if args.episodes < 1 or args.steps < 1 or not args.seconds > 0:
        ap.error("--episodes and --steps must be >= 1, --seconds > 0")
    from experiments.runtime.executors import limit_blas_threads

    limit_blas_threads()
    res = {**bench_step(args.steps), **bench_rollouts(args.episodes, args.seconds)}
    res["text"] = "\n".join([
        f"WalkEngine.step: median {res['step_us_median']:.1f} µs, p90 {res['step_us_p90']:.1f} µs "
        f"({args.steps} calls; target <= 100 µs median)",
        f"walk of θ0, {args.seconds:g} s in the sim: median {res['rollout_wall_s_median']:.3f} s "
        f"({res['rollouts_per_s']:.2f} walks/s, {res['speed_cm_s']:.2f} cm/s), bare mj_step of its "
        f"{res['physics_steps']} physics steps: median {res['bare_mj_step_s_median']:.3f} s",
        f"rollout / bare: {res['rollout_over_bare']:.2f} (median over {args.episodes} paired walks; 1.0 = the physics limit)",
    ])
    print(json.dumps(res) if args.json else res["text"], flush=True)
    return res


if __name__ == "__main__":
    main()
