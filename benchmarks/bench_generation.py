"""One paper-scale CMA-ES generation, batched, beside bare ``mj_step`` of the same steps.

A population of ``--popsize`` (default 150, the paper's) gaits is drawn by CMA-ES around θ0 exactly
as ``sgatwalk optimize`` draws a first generation (trust region, σ0, bounds), one 7.5 s episode
each, in the plain sim and in the grounded sim (an SGAT transformer fitted first, as ``optimize``'s
first grounding step fits it: 4 real and 4 sim walks of θ0, α 0.5, 5-member ensemble). Per world, in
one process (one core), interleaved over ``--repeats``:

* **batched**: the generation as the executors run it (``experiments.runtime.batch.map_episodes``: lock-step
  batches of ``popsize / workers``, here run one after the other on this core);
* **single**: the same episodes one at a time (``experiments.runtime.tasks.run_episode``, the path before
  batching), on a sample of ``--single`` episodes;
* **bare, sequential**: ``mujoco.mj_step(m, d, nstep=10)`` with each episode's own applied actions,
  one episode after the other on one ``MjData`` (the physics alone, cache-hot);
* **bare, lock-step**: the same steps across the batch's ``MjData`` in lock-step (the physics alone
  with the batch's memory traffic).

The ratios bare / batched (and bare / single) say how close a rollout runs to the physics limit
(1.0 = no overhead). A generation on ``--workers`` idle cores takes about the per-core batched time
divided by the cores. Prints a table (medians over repeats) or, with ``--json``, one JSON object;
``--save NAME`` also writes ``docs/results/NAME.json`` for the README (with the load average).

Usage: ``python benchmarks/bench_generation.py [--popsize 150] [--repeats 3] [--save bench-generation]``
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

import numpy as np  # noqa: E402

from envs import Recording  # noqa: E402
from experiments.runtime.batch import chunk_tasks, map_episodes, run_batch  # noqa: E402
from experiments.runtime.executors import SerialExecutor  # noqa: E402
from experiments.runtime.grounding import DEFAULT_GROUNDING, EXPLORATION_NOISE, REAL_WALKS, SIM_WALKS, fit_nao_grounding  # noqa: E402
from experiments.optimize.run import OptimizeConfig  # noqa: E402
from experiments.runtime.tasks import _world, run_episode  # noqa: E402
from walk_engine import GaitParams  # noqa: E402


def population(n: int, seed: int) -> list[list[float]]:
    """A first CMA-ES generation around θ0 with ``optimize``'s settings."""
    import cma

    cfg = OptimizeConfig()
    x0 = GaitParams().to_vector()
    lo, hi = np.clip(x0 - cfg.trust_region, 0, 1), np.clip(x0 + cfg.trust_region, 0, 1)
    es = cma.CMAEvolutionStrategy(x0, cfg.sigma0, {"bounds": [lo.tolist(), hi.tolist()], "popsize": n, "verbose": -9,
                                                    "randn": np.random.RandomState(seed).randn})
    return [GaitParams.from_vector(x, clip=True).to_array().tolist() for x in es.ask()]


def fit_transformer(out: str, seed: int) -> str:
    """``optimize``'s first grounding step on θ0: real and sim walks, then the SGAT ensemble."""
    th0 = GaitParams().to_array().tolist()
    ex = SerialExecutor()
    real = map_episodes(ex, [{"world": "real", "theta": th0, "seed": 1000 + i, "record": True} for i in range(REAL_WALKS)])
    sim = map_episodes(ex, [{"world": "sim", "theta": th0, "seed": 2000 + i, "record": True,
                             "action_noise": EXPLORATION_NOISE} for i in range(SIM_WALKS)])
    fit = fit_nao_grounding([Recording(*r["recording"]) for r in real], [Recording(*r["recording"]) for r in sim],
                            DEFAULT_GROUNDING, seed=seed)
    fit.transformer.save(out)
    return out


def _applied(rec) -> np.ndarray:
    cols, _ = rec
    names = [c for c in cols if c.startswith("app.")]
    return np.stack([cols[c] for c in names], axis=1)


def bare(tasks: list[dict], actions: list[np.ndarray], chunks: list[list[int]], lockstep: bool) -> float:
    """Seconds of bare ``mj_step`` replaying each episode's applied actions (see module docstring)."""
    import mujoco

    env = _world({**tasks[0], "world": "sim", "action_noise": 0.0}).unwrapped
    m, expand = env.model, env.robot.actuated_to_joint
    own = env.data
    total = 0.0
    try:
        for c in chunks:
            datas = []
            for i in c:
                env.data = mujoco.MjData(m)
                env.reset(seed=tasks[i]["seed"])
                datas.append(env.data)
            ctrl = [actions[i][:, expand] for i in c]
            t0 = time.perf_counter()
            if lockstep:
                for k in range(max(len(u) for u in ctrl)):
                    for d, u in zip(datas, ctrl):
                        if k < len(u):
                            d.ctrl[:] = u[k]
                            mujoco.mj_step(m, d, nstep=env.n_substeps)
            else:
                for d, u in zip(datas, ctrl):
                    for row in u:
                        d.ctrl[:] = row
                        mujoco.mj_step(m, d, nstep=env.n_substeps)
            total += time.perf_counter() - t0
    finally:
        env.data = own
    return total


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--popsize", type=int, default=150)
    ap.add_argument("--workers", type=int, default=2, help="batches are cut as for this many workers (default 2)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--single", type=int, default=12, help="episodes timed one at a time per repeat (default 12)")
    ap.add_argument("--seconds", type=float, default=7.5)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--save", metavar="NAME", help="also write docs/results/NAME.json")
    args = ap.parse_args(argv)
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:  # pragma: no cover
        pass
    load_before = os.getloadavg()[0]
    t_start = time.perf_counter()

    def say(msg):
        print(f"[{time.perf_counter() - t_start:6.0f} s] {msg}", file=sys.stderr, flush=True)

    thetas = population(args.popsize, args.seed)
    tmp = tempfile.mkdtemp(prefix="bench_generation_")
    say("fitting the grounding transformer (optimize's first step on θ0)")
    tr = fit_transformer(os.path.join(tmp, "sgat"), args.seed)
    worlds = {"sim": {"world": "sim"}, "grounded": {"world": "grounded", "transformer": tr}}
    out = {"popsize": args.popsize, "workers": args.workers, "seconds": args.seconds, "repeats": args.repeats,
           "worlds": {}}
    for name, kw in worlds.items():
        tasks = [{**kw, "theta": th, "seed": 7 + i, "seconds": args.seconds} for i, th in enumerate(thetas)]
        chunks = chunk_tasks(tasks, args.workers)
        say(f"{name}: recording the applied actions of {len(tasks)} episodes")
        recs = run_batch([{**t, "record": True} for t in tasks])
        actions = [_applied(r["recording"]) for r in recs]
        steps = int(sum(len(a) for a in actions))
        sample = list(range(0, len(tasks), max(1, len(tasks) // args.single)))[:args.single]
        times = {"batched": [], "single": [], "bare_seq": [], "bare_lock": [], "bare_seq_sample": []}
        for rep in range(args.repeats):
            t0 = time.perf_counter()
            res = [r for c in chunks for r in run_batch([tasks[i] for i in c])]
            times["batched"].append(time.perf_counter() - t0)
            times["bare_lock"].append(bare(tasks, actions, chunks, lockstep=True))
            times["bare_seq"].append(bare(tasks, actions, [list(range(len(tasks)))], lockstep=False))
            t0 = time.perf_counter()
            single = [run_episode(tasks[i]) for i in sample]
            times["single"].append(time.perf_counter() - t0)
            times["bare_seq_sample"].append(bare(tasks, actions, [sample], lockstep=False))
            assert [r["fitness"] for r in single] == [res[i]["fitness"] for i in sample]  # bit-identical
            say(f"{name} repeat {rep + 1}/{args.repeats}: batched {times['batched'][-1]:.1f} s, bare "
                f"{times['bare_seq'][-1]:.1f} s (lock-step {times['bare_lock'][-1]:.1f} s), {len(sample)} single "
                f"episodes {times['single'][-1]:.1f} s")
        med = {k: statistics.median(v) for k, v in times.items()}
        ratios = {
            "batched_vs_bare": statistics.median(b / a for a, b in zip(times["batched"], times["bare_seq"])),
            "batched_vs_bare_lockstep": statistics.median(b / a for a, b in zip(times["batched"], times["bare_lock"])),
            "single_vs_bare": statistics.median(b / a for a, b in zip(times["single"], times["bare_seq_sample"])),
        }
        out["worlds"][name] = {
            "episodes": len(tasks), "falls": int(sum(r["fell"] for r in res)), "control_steps": steps,
            "batches": [len(c) for c in chunks], "median_s": med, "ratios": ratios,
            "generation_s_per_core": med["batched"],
            "generation_s_on_workers": med["batched"] / args.workers,
            "physics_limit_s_on_workers": med["bare_seq"] / args.workers,
            "single_episode_ms": 1000 * med["single"] / len(sample),
            "batched_episode_ms": 1000 * med["batched"] / len(tasks),
        }
    out["load_before"], out["load_after"] = load_before, os.getloadavg()[0]
    out["table"] = format_table(out)
    if args.save:
        from tools.readme import save

        cmd = "python benchmarks/bench_generation.py " + " ".join(a for a in (argv if argv is not None else sys.argv[1:])
                                                                   if not a.startswith("--save") and a != args.save)
        save(args.save, cmd.strip(), out, machine={"cpus": os.cpu_count(), "load_before": load_before,
                                                   "load_after": out["load_after"]})
    print(json.dumps(out) if args.json else out["table"], flush=True)
    return 0


def format_table(out: dict) -> str:
    """The benchmark's table (plain text)."""
    lines = [f"population {out['popsize']} x 1 episode of {out['seconds']} s, batches for {out['workers']} workers, "
             f"medians of {out['repeats']} repeats on one core",
             f"{'world':<9} {'falls':>5} {'steps':>7} {'batched s':>9} {'bare s':>7} {'batched/bare':>12} "
             f"{'(lock-step)':>11} {'single/bare':>11} {'gen. on ' + str(out['workers']) + ' cores':>14} "
             f"{'limit':>6}"]
    for name, w in out["worlds"].items():
        r = w["ratios"]
        lines.append(f"{name:<9} {w['falls']:>5} {w['control_steps']:>7} {w['median_s']['batched']:>9.1f} "
                     f"{w['median_s']['bare_seq']:>7.1f} {r['batched_vs_bare']:>12.2f} {r['batched_vs_bare_lockstep']:>11.2f} "
                     f"{r['single_vs_bare']:>11.2f} {w['generation_s_on_workers']:>12.1f} s {w['physics_limit_s_on_workers']:>4.1f} s")
    lines.append("ratios: bare mj_step time / rollout time for the same control steps (1.0 = the physics limit); "
                 "'single' = one episode at a time (run_episode)")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
