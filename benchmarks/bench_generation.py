"""How close does a paper-scale CMA-ES generation, batched, run to bare ``mj_step`` of the same steps?

A population of ``--popsize`` (default 150, the paper's) gaits is drawn by CMA-ES around θ0 exactly
as ``sgatwalk optimize`` draws a first generation (trust region, σ0, bounds), one 7.5 s episode
each, in the plain sim and in the grounded sim (an SGAT transformer fitted first, as ``optimize``'s
first grounding step fits it with the options of the world ``sgat``: its real and sim walks of θ0,
the sim walks with its exploration noise, its history, α, ensemble and models). Per world, in one
process (one core), interleaved over ``--repeats``:

* **batched**: the generation as the executors run it (``experiments.runtime.batch.run_batch`` on the
  lock-step batches ``map_episodes`` cuts for ``--workers``, here run one after the other on this core);
* **single**: the same episodes one at a time (``experiments.runtime.tasks.run_episode``, the path
  without batching), on a sample of ``--single`` episodes (their results must equal the batched ones);
* **bare, sequential**: ``mujoco.mj_step(m, d, nstep=10)`` with each episode's own applied actions,
  one episode after the other on one ``MjData`` (the physics alone, cache-hot);
* **bare, lock-step**: the same steps across the batch's ``MjData`` in lock-step (the physics alone
  with the batch's memory traffic).

The ratios bare / batched (and bare / single), medians over the repeats of each repeat's ratio, say
how close a rollout runs to the physics limit (1.0 = no overhead). A generation on ``--workers``
idle cores takes about the per-core batched time divided by the cores. Prints a table (medians over
the repeats) or, with ``--json``, one JSON object (its ``"text"`` the table); progress goes to stderr.

Defaults (population 150, 2 repeats) take about 6 minutes on 2 idle cores (a repeat about 2.5 minutes
for both worlds, the grounding walks and fit about 1.5 minutes); ``--repeats 1`` about 4.

Usage: ``python benchmarks/bench_generation.py [--popsize 150] [--repeats 2] [--json]``
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
from experiments.optimize.run import OptimizeConfig  # noqa: E402
from experiments.runtime.batch import chunk_tasks, map_episodes, run_batch  # noqa: E402
from experiments.runtime.executors import SerialExecutor  # noqa: E402
from experiments.runtime.grounding import fit_walk_grounding  # noqa: E402
from experiments.runtime.tasks import EpisodeTask, run_episode  # noqa: E402
from experiments.runtime.worlds import parse_world, world_env  # noqa: E402
from walk_engine import GaitParams  # noqa: E402

#: The training world whose first grounding step the grounded generation walks in.
WORLD = "sgat"


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
    """``optimize``'s first grounding step on θ0 in the world :data:`WORLD`: its real walks and its sim
    walks with exploration noise, then its SGAT ensemble, saved to ``out``."""
    spec = parse_world(WORLD)
    th0 = GaitParams().to_array().tolist()
    ex = SerialExecutor()
    real = map_episodes(ex, [EpisodeTask("real", th0, 1000 + i, record=True) for i in range(int(spec.get("real")))])
    sim = map_episodes(ex, [EpisodeTask("sim", th0, 2000 + i, record=True, action_noise=float(spec.get("explore")))
                            for i in range(int(spec.get("sim")))])
    fit = fit_walk_grounding([Recording(*r.recording) for r in real], [Recording(*r.recording) for r in sim],
                             spec.grounding_config(), history=int(spec.get("history")), seed=seed)
    fit.transformer.save(out)
    return out


def _applied(rec) -> np.ndarray:
    """The applied actions (``app.*`` columns) of a result's ``(columns, meta)`` recording, (T, actuated)."""
    cols, _ = rec
    names = [c for c in cols if c.startswith("app.")]
    return np.stack([cols[c] for c in names], axis=1)


def bare(tasks: list[EpisodeTask], actions: list[np.ndarray], chunks: list[list[int]], lockstep: bool) -> float:
    """Seconds of bare ``mj_step`` replaying each episode's applied actions (see module docstring)."""
    import mujoco

    env = world_env(tasks[0]).unwrapped  # the plain sim: the physical world of both worlds' tasks
    m, expand = env.model, env.robot.actuated_to_joint
    own = env.data
    total = 0.0
    try:
        for c in chunks:
            datas = []
            for i in c:
                env.data = mujoco.MjData(m)
                env.reset(seed=tasks[i].seed)
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
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 epilog="About 6 minutes at the defaults on 2 idle cores (--repeats 1: about 4).")
    ap.add_argument("--popsize", type=int, default=150, help="gaits of the generation (default 150, the paper's)")
    ap.add_argument("--workers", type=int, default=2, help="batches are cut as for this many workers (default 2)")
    ap.add_argument("--repeats", type=int, default=2, help="interleaved repeats per world (default 2)")
    ap.add_argument("--single", type=int, default=12, help="episodes timed one at a time per repeat (default 12)")
    ap.add_argument("--seconds", type=float, default=7.5, help="episode length [s] (default 7.5, the paper's)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the population and the grounding fit (default 0)")
    ap.add_argument("--json", action="store_true", help="print one JSON object (its \"text\": the table)")
    args = ap.parse_args(argv)
    if min(args.popsize, args.workers, args.repeats, args.single) < 1 or not args.seconds > 0 or args.seed < 0:
        ap.error("--popsize, --workers, --repeats and --single must be >= 1, --seconds > 0, --seed >= 0")
    from experiments.runtime.executors import limit_blas_threads

    limit_blas_threads()
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:  # pragma: no cover
        pass
    t_start = time.perf_counter()

    def say(msg):
        print(f"[{time.perf_counter() - t_start:6.0f} s] {msg}", file=sys.stderr, flush=True)

    thetas = population(args.popsize, args.seed)
    say("fitting the grounding transformer (optimize's first step on θ0)")
    with tempfile.TemporaryDirectory(prefix="bench_generation_") as tmp:
        out = measure(args, thetas, fit_transformer(os.path.join(tmp, "sgat"), args.seed), say)
    out["text"] = format_table(out)
    print(json.dumps(out) if args.json else out["text"], flush=True)
    return 0


def measure(args, thetas: list, tr: str, say) -> dict:
    """Every timing of both worlds (module docstring): the generation ``thetas`` in the plain sim and in
    the sim grounded by the transformer saved in ``tr``."""
    worlds = {"sim": None, "grounded": tr}
    out = {"popsize": args.popsize, "workers": args.workers, "seconds": args.seconds, "repeats": args.repeats,
           "grounded_world": WORLD, "worlds": {}}
    for name, transformer in worlds.items():
        tasks = [EpisodeTask("sim", th, 7 + i, args.seconds, transformer=transformer) for i, th in enumerate(thetas)]
        chunks = chunk_tasks(tasks, args.workers)
        say(f"{name}: recording the applied actions of {len(tasks)} episodes")
        recs = run_batch([t.replace(record=True) for t in tasks])
        actions = [_applied(r.recording) for r in recs]
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
            if [r.metrics() for r in single] != [res[i].metrics() for i in sample]:  # bit-identical
                raise SystemExit(f"{name}: run_episode and run_batch disagree on the sampled episodes")
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
            "episodes": len(tasks), "falls": int(sum(r.fell for r in res)), "control_steps": steps,
            "batches": [len(c) for c in chunks], "median_s": med, "ratios": ratios,
            "generation_s_per_core": med["batched"],
            "generation_s_on_workers": med["batched"] / args.workers,
            "physics_limit_s_on_workers": med["bare_seq"] / args.workers,
            "single_episode_ms": 1000 * med["single"] / len(sample),
            "batched_episode_ms": 1000 * med["batched"] / len(tasks),
        }
    return out


def format_table(out: dict) -> str:
    """The benchmark's table (plain text)."""
    lines = [f"population {out['popsize']} x 1 episode of {out['seconds']} s, batches for {out['workers']} workers, "
             f"medians of {out['repeats']} interleaved repeats on one core",
             f"{'world':<9} {'falls':>5} {'steps':>7} {'batched s':>9} {'bare s':>7} {'bare/batched':>12} "
             f"{'(lock-step)':>11} {'bare/single':>11} {'gen. on ' + str(out['workers']) + ' cores':>14} "
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
