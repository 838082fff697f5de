"""How do the experiments scale beyond one process? Serial, process pool and Ray, side by side in one run.

Three measurements on this machine, then a projection:

* **Dispatch overhead per task**: ``--noops`` tasks that do nothing, through a process pool and a local
  Ray cluster of ``--workers`` workers (milliseconds per task beyond the work itself).
* **Episodes**: ``--episodes`` real-world episodes of θ0 (``--seconds`` each; the PyBullet world,
  the experiments' most expensive unit) run serially, on a pool of 1 and ``--workers`` processes and on a
  local Ray cluster with 1 and ``--workers`` CPUs. Every way must give the same fitness, bit for bit.
  Medians over ``--repeats`` interleaved repeats; speed-up against serial.
* **A whole Table I**: ``sgatwalk table1`` on small settings (``--methods sgat,sim --seeds 2``, 2 s
  episodes) with 1 and ``--workers`` worker processes: the measured speed-up S gives the serial fraction
  by the Karp-Flatt metric, e = (1/S - 1/p) / (1 - 1/p) (Karp and Flatt, CACM 33(5), 1990), the
  fraction Amdahl's law says bounds the speed-up on any number of cores.

**Projection** (with ``--table1-hours`` and ``--gym-hours``, the measured wall time of a run on this
machine's ``--workers`` cores): the run's jobs (Table I's optimizations, gym's cells) run side by side,
each by Amdahl's law with its serial fraction (Table I: the Karp-Flatt fraction above; a gym cell: 1,
one process); see :func:`project`. Printed for 16, 64 and 256 cores.

Prints a table or, with ``--json``, one JSON object (its ``"text"`` the table); progress goes to stderr.
Exits 1 if the executors disagree. Defaults take about 10 minutes on 2 idle cores.

Usage: ``python benchmarks/bench_scaling.py [--episodes 8] [--seconds 2] [--repeats 3] [--workers 2]
[--noops 200] [--table1-hours H --table1-jobs 25] [--gym-hours H --gym-jobs 250] [--json]``
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
os.environ.setdefault("OMP_NUM_THREADS", "1")

#: Cores the projection is made for.
PROJECT_CORES = (16, 64, 256)


def noop(x):
    """A task that does nothing (the dispatch overhead alone)."""
    return x


def warm(x):
    """Import the engines in a worker, so that the clock measures episodes, not a worker's first imports."""
    import mujoco  # noqa: F401
    import pybullet  # noqa: F401

    import envs  # noqa: F401
    from experiments.runtime import batch  # noqa: F401

    return x


def karp_flatt(speedup: float, p: int) -> float:
    """The experimentally determined serial fraction e = (1/S - 1/p) / (1 - 1/p) of a speed-up S on p
    processors (Karp and Flatt 1990); 0: perfectly parallel, 1: serial."""
    return (1.0 / speedup - 1.0 / p) / (1.0 - 1.0 / p)


def project(hours_p: float, speedup: float, p: int, jobs: int, job_serial_fraction: float | None = None,
            cores=PROJECT_CORES) -> dict:
    """Wall time [h] on ``cores`` of a run made of ``jobs`` independent jobs that a cluster runs side by side.

    The run took ``hours_p`` on ``p`` workers with speed-up ``speedup`` there, so T1 = hours_p x speedup
    on one core and t = T1 / jobs per job. Within a job, Amdahl's law (Amdahl 1967) with the serial
    fraction e (``job_serial_fraction``, default the Karp-Flatt fraction of the measured speed-up): on
    N >= jobs cores each job has N / jobs cores, T(N) = t (e + (1 - e) jobs / N); on fewer cores the
    jobs run in ceil(jobs / N) waves of one core each, T(N) = ceil(jobs / N) t.

    Returns:
        ``{"16": hours, "64": ..., "serial_fraction": e, "t1_hours": T1, "job_hours": t}``.
    """
    e = karp_flatt(speedup, p) if job_serial_fraction is None else job_serial_fraction
    e = min(max(e, 0.0), 1.0)
    t1 = hours_p * speedup
    t = t1 / jobs
    out = {str(n): (t * (e + (1 - e) * jobs / n) if n >= jobs else math.ceil(jobs / n) * t) for n in cores}
    return out | {"serial_fraction": e, "t1_hours": t1, "job_hours": t}


def _ray(cpus: int):
    import ray

    ray.init(num_cpus=cpus, include_dashboard=False, log_to_driver=False,
             runtime_env={"env_vars": {"PYTHONPATH": ROOT, "OMP_NUM_THREADS": "1"}})
    from experiments.runtime.executors import RayExecutor

    return RayExecutor(None)


def _executors(workers: int):
    from experiments.runtime.executors import ProcessExecutor, SerialExecutor

    return [("serial", 1, SerialExecutor), ("pool", 1, lambda: ProcessExecutor(1)),
            ("pool", workers, lambda: ProcessExecutor(workers)), ("ray", 1, lambda: _ray(1)),
            ("ray", workers, lambda: _ray(workers))]


def time_episodes(args, say) -> tuple[list[dict], bool]:
    """Real-world episodes through every executor, interleaved over repeats. Returns rows and whether
    every executor gave the same fitness."""
    import ray

    from experiments.runtime.batch import map_episodes
    from experiments.runtime.tasks import EpisodeTask
    from walk_engine import GaitParams

    theta = tuple(GaitParams.initial().to_array())
    tasks = [EpisodeTask("real", theta, 1000 + i, args.seconds) for i in range(args.episodes)]
    walls: dict[tuple, list[float]] = {}
    fitness: dict[tuple, list] = {}
    for rep in range(args.repeats):
        for name, n, make in _executors(args.workers):
            ex = make()
            try:
                if name != "serial":
                    ex.map(warm, list(range(4 * n)))  # workers up, engines imported, before the clock starts
                t0 = time.perf_counter()
                res = map_episodes(ex, tasks)
                walls.setdefault((name, n), []).append(time.perf_counter() - t0)
                fitness[(name, n)] = [r.fitness for r in res]
            finally:
                ex.close()
                if name == "ray":
                    ray.shutdown()
            say(f"repeat {rep + 1}/{args.repeats}: {name} x{n}: {walls[(name, n)][-1]:.1f} s")
    serial = statistics.median(walls[("serial", 1)])
    rows = [{"executor": name, "workers": n, "wall_s": statistics.median(w), "speedup": serial / statistics.median(w),
             "serial_fraction": karp_flatt(serial / statistics.median(w), n) if n > 1 else None}
            for (name, n), w in walls.items()]
    same = len({tuple(v) for v in fitness.values()}) == 1
    return rows, same


def time_dispatch(args, say) -> list[dict]:
    """Milliseconds per do-nothing task through a pool and a Ray cluster of ``args.workers``."""
    import ray

    from experiments.runtime.executors import ProcessExecutor

    out = []
    for name, make in (("pool", lambda: ProcessExecutor(args.workers)), ("ray", lambda: _ray(args.workers))):
        ex = make()
        try:
            ex.map(noop, list(range(2 * args.workers)))
            t = []
            for _ in range(args.repeats):
                t0 = time.perf_counter()
                ex.map(noop, list(range(args.noops)))
                t.append((time.perf_counter() - t0) / args.noops)
        finally:
            ex.close()
            if name == "ray":
                ray.shutdown()
        out.append({"executor": name, "workers": args.workers, "ms_per_task": 1000 * statistics.median(t)})
        say(f"dispatch: {name}: {out[-1]['ms_per_task']:.2f} ms per task")
    return out


def time_table1(args, say) -> dict:
    """A small ``sgatwalk table1`` with 1 and ``args.workers`` workers: wall times, speed-up, serial fraction."""
    walls = {}
    for n in (1, args.workers):
        out = tempfile.mkdtemp(prefix="bench_scaling_")
        try:
            cmd = [sys.executable, "-m", "experiments.cli", "table1", "--methods", "sgat,sim", "--seeds", "2",
                   "--trials", "4", "--popsize", "4", "--generations", "2", "--grounding-steps", "1", "--seconds",
                   str(args.seconds), "--workers", str(n), "--out", out, "--json"]
            t0 = time.perf_counter()
            subprocess.run(cmd, cwd=ROOT, check=True, capture_output=True, env={**os.environ, "PYTHONPATH": ROOT})
            walls[n] = time.perf_counter() - t0
        finally:
            shutil.rmtree(out, ignore_errors=True)
        say(f"table1 on {n} worker(s): {walls[n]:.0f} s")
    s = walls[1] / walls[args.workers]
    return {"wall_s": {str(k): v for k, v in walls.items()}, "speedup": s, "serial_fraction": karp_flatt(s, args.workers)}


def format_text(res: dict) -> str:
    lines = [f"scaling on {res['cpu']} ({res['cores']} cores); {res['episodes']} real episodes of {res['seconds']:g} s, "
             f"medians of {res['repeats']}", "", f"{'executor':<8} {'workers':>7} {'wall [s]':>9} {'speed-up':>9} {'serial fraction':>16}"]
    for r in res["episodes_rows"]:
        e = "-" if r["serial_fraction"] is None else f"{r['serial_fraction']:.3f}"
        lines.append(f"{r['executor']:<8} {r['workers']:>7} {r['wall_s']:>9.1f} {r['speedup']:>9.2f} {e:>16}")
    lines.append(f"every executor gave the same fitness: {'yes' if res['identical'] else 'NO'}")
    lines.append("")
    for d in res["dispatch"]:
        lines.append(f"dispatch overhead, {d['executor']} x{d['workers']}: {d['ms_per_task']:.2f} ms per task")
    t = res.get("table1")
    if t:
        lines.append(f"table1 (small): {t['wall_s']['1']:.0f} s on 1 worker, {t['wall_s'][str(res['workers'])]:.0f} s on "
                     f"{res['workers']}: speed-up {t['speedup']:.2f}, serial fraction {t['serial_fraction']:.3f}")
    for key, label in (("table1_projection", "table1"), ("gym_projection", "gym --preset paper")):
        pr = res.get(key)
        if pr:
            lines.append(f"projected {label}: " + ", ".join(f"{n} cores {pr[str(n)]:.1f} h" for n in PROJECT_CORES)
                         + f" (1 core {pr['t1_hours']:.1f} h; a job {pr['job_hours']:.2f} h, its serial fraction "
                           f"{pr['serial_fraction']:.3f})")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--episodes", type=int, default=8)
    ap.add_argument("--seconds", type=float, default=2.0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--noops", type=int, default=200)
    ap.add_argument("--no-table1", action="store_true", help="skip the whole-Table-I measurement")
    ap.add_argument("--table1-hours", type=float, help="measured wall time [h] of a full table1 run on --workers cores")
    ap.add_argument("--table1-jobs", type=int, default=25, help="its optimizations (methods x seeds; default 5 x 5)")
    ap.add_argument("--gym-hours", type=float, help="measured or estimated wall time [h] of gym --preset paper on --workers cores")
    ap.add_argument("--gym-jobs", type=int, default=250, help="its cells (noise x methods x runs)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    if min(args.episodes, args.repeats, args.noops) < 1 or args.workers < 2 or args.seconds <= 0:
        ap.error("--episodes, --repeats, --noops >= 1, --workers >= 2, --seconds > 0")

    def say(msg):
        print(f"[bench_scaling] {msg}", file=sys.stderr, flush=True)

    from tools.results import cpu_model

    rows, same = time_episodes(args, say)
    res = {"cpu": cpu_model(), "cores": os.cpu_count(), "episodes": args.episodes, "seconds": args.seconds,
           "repeats": args.repeats, "workers": args.workers, "episodes_rows": rows, "identical": same,
           "dispatch": time_dispatch(args, say)}
    if not args.no_table1:
        res["table1"] = time_table1(args, say)
        if args.table1_hours:
            res["table1_projection"] = project(args.table1_hours, res["table1"]["speedup"], args.workers, args.table1_jobs)
    pool = next(r for r in rows if r["executor"] == "pool" and r["workers"] == args.workers)
    if args.gym_hours:  # gym cells are whole training runs, each one process: serial within a cell
        res["gym_projection"] = project(args.gym_hours, pool["speedup"], args.workers, args.gym_jobs, 1.0)
    res["text"] = format_text(res)
    print(json.dumps(res) if args.json else res["text"], flush=True)
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
