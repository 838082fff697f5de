"""What does grounding cost a walk? A grounded walk against an ungrounded one against bare ``mj_step``.

Times, interleaved over ``--repeats`` (medians, and each figure's ratio to bare ``mj_step``):

* bare ``mujoco.mj_step`` for the physics of a 7.5 s episode (7 500 steps at 1 kHz);
* an ungrounded θ0 walk in the sim (walk engine + env + recording);
* the same walk in ``sgat.GroundedEnv`` with an SGAT transformer shaped as the training world
  ``--world`` fits it (default ``sgat``: its models, history, ensemble and α; NumPy inference), with
  weights fitted on synthetic data (the cost is what matters), and the transformer call alone per
  control step.

With ``--generation``, also one CMA-ES generation (``--popsize``, default 150) of 7.5 s episodes in that
grounded sim, through the default process pool in lock-step batches
(``experiments.runtime.batch.map_episodes``, as ``sgatwalk optimize`` runs one).

Prints its lines, or one JSON object with ``--json`` (its ``"text"`` the lines); progress goes to
stderr. Defaults (5 repeats) take about 15 s on 2 idle cores; ``--generation`` adds about 20 s.

Usage: ``python benchmarks/bench_grounding.py [--repeats 5] [--world sgat] [--generation [--popsize 150]] [--json]``
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


def synthetic_transformer(env, world: str, rng: np.random.Generator):
    """An SGAT transformer of the shape ``world`` fits (its grounding spec, models, ensemble, α), with
    weights fitted for 2 epochs on random data: what a call costs, not what it returns.

    Raises:
        ValueError: ``world`` is not a grounded world, or grounds with a delay (the walk here gives no
            past actions).
    """
    from experiments.runtime.grounding import grounding_spec
    from experiments.runtime.worlds import parse_world
    from sgat.models import ForwardModel, InverseModel
    from sgat.transformer import ActionTransformer

    spec_w = parse_world(world)
    cfg = spec_w.grounding_config(delay=0)
    if cfg is None or cfg.delay:
        raise ValueError(f"world {spec_w.name!r}: give a grounded world without a delay (gat, sgat, hybrid)")
    spec = grounding_spec(env, int(spec_w.get("history")))
    S, A, k = spec.state_dim, spec.action_dim, spec.history
    pose = env.robot.pose("crouch", actuated=True)[spec.action_index]
    fwds, invs = [], []
    for m in range(cfg.ensemble):
        fwd = ForwardModel(S, A, history=k, stochastic=cfg.method == "sgat", hidden=cfg.hidden, components=cfg.components)
        inv = InverseModel(S, A, history=k, hidden=cfg.hidden)
        fwd.fit(rng.normal(size=(400, k * S + A)), rng.normal(size=(400, S)) * 1e-3, max_epochs=2, seed=m)
        inv.fit(rng.normal(size=(400, k * S + S)), pose + rng.normal(size=(400, A)) * 1e-3, max_epochs=2, seed=m)
        fwds.append(fwd)
        invs.append(inv)
    return ActionTransformer(spec, fwds, invs, method=cfg.method, alpha=cfg.alpha), spec_w.name


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 epilog="About 15 s at the defaults on 2 idle cores; --generation adds about 20 s.")
    ap.add_argument("--repeats", type=int, default=5, help="interleaved repeats (default 5)")
    ap.add_argument("--world", default="sgat",
                    help="the grounded training world whose transformer shape is timed (default sgat; e.g. "
                         "sgat:hidden=64x64:history=1, the paper's)")
    ap.add_argument("--generation", action="store_true", help="also time one CMA-ES generation of grounded episodes")
    ap.add_argument("--popsize", type=int, default=150, help="population of that generation (default 150, the paper's)")
    ap.add_argument("--workers", type=int, default=None, help="workers of the generation's pool (default: one per core)")
    ap.add_argument("--json", action="store_true", help="print one JSON object (its \"text\": the lines)")
    args = ap.parse_args(argv)
    if args.repeats < 1 or args.popsize < 1 or (args.workers is not None and args.workers < 1):
        ap.error("--repeats, --popsize and --workers must be >= 1")

    import mujoco

    from envs import SimWorld
    from experiments.runtime.executors import limit_blas_threads
    from experiments.runtime.fitness import run_walk
    from sgat.transformer import GroundedEnv
    from walk_engine import GaitParams

    limit_blas_threads()
    import torch

    torch.set_num_threads(1)
    sim = SimWorld()
    rng = np.random.default_rng(0)
    try:
        tr, world = synthetic_transformer(sim, args.world, rng)
    except ValueError as exc:
        ap.error(str(exc))
    spec = tr.spec
    grounded = GroundedEnv(SimWorld(), tr)
    p0 = GaitParams.initial()

    def bare():
        sim.reset(seed=0)
        sim.data.ctrl[:] = sim.robot.pose("crouch")
        t = time.perf_counter()
        mujoco.mj_step(sim.model, sim.data, nstep=7500)
        return time.perf_counter() - t

    def walk(env):
        t = time.perf_counter()
        run_walk(p0, seed=0, seconds=7.5, env=env)
        return time.perf_counter() - t

    def transform():
        h = rng.normal(size=spec.history * spec.state_dim)
        a = sim.robot.pose("crouch", actuated=True)[spec.action_index]
        t = time.perf_counter()
        for _ in range(750):
            tr.transform(h, a)
        return (time.perf_counter() - t) / 750

    res = {"bare mj_step (7500 steps)": [], "ungrounded walk": [], "grounded walk (SGAT)": [], "transformer call": []}
    for r in range(args.repeats):
        res["bare mj_step (7500 steps)"].append(bare())
        res["ungrounded walk"].append(walk(sim))
        res["grounded walk (SGAT)"].append(walk(grounded))
        res["transformer call"].append(transform())
        print(f"[bench_grounding] repeat {r + 1}/{args.repeats} done", file=sys.stderr, flush=True)
    med = {k: statistics.median(v) for k, v in res.items()}
    b = med["bare mj_step (7500 steps)"]
    lines = [f"7.5 s episode, medians of {args.repeats} interleaved runs; transformer of the world {world} "
             f"({tr.n_members} member(s), history {spec.history}, "
             f"{'linear models' if not tr.forward.hidden else 'hidden ' + 'x'.join(map(str, tr.forward.hidden))})"]
    for k in ("bare mj_step (7500 steps)", "ungrounded walk", "grounded walk (SGAT)"):
        lines.append(f"  {k:28s} {med[k]:7.3f} s   {med[k] / b:5.2f} x bare")
    lines.append(f"  grounded / ungrounded walk     {med['grounded walk (SGAT)'] / med['ungrounded walk']:.2f}")
    lines.append(f"  transformer call               {1e6 * med['transformer call']:.1f} µs per control step "
                 f"({100 * 750 * med['transformer call'] / med['grounded walk (SGAT)']:.1f} % of a grounded episode)")
    out = {"repeats": args.repeats, "world": world, "members": tr.n_members, "history": spec.history,
           "median_s": med, "bare_s": b, "ungrounded_over_bare": med["ungrounded walk"] / b,
           "grounded_over_bare": med["grounded walk (SGAT)"] / b,
           "grounded_over_ungrounded": med["grounded walk (SGAT)"] / med["ungrounded walk"],
           "transformer_call_us": 1e6 * med["transformer call"],
           "transformer_share_of_grounded": 750 * med["transformer call"] / med["grounded walk (SGAT)"]}

    if args.generation:
        from experiments.runtime.batch import map_episodes
        from experiments.runtime.executors import make_executor
        from experiments.runtime.tasks import EpisodeTask

        print(f"[bench_grounding] one generation of {args.popsize} grounded episodes", file=sys.stderr, flush=True)
        with tempfile.TemporaryDirectory() as tmp:
            tr.save(tmp)
            theta = p0.to_vector()
            tasks = [EpisodeTask("sim", GaitParams.from_vector(np.clip(theta + 0.1 * rng.normal(size=16), 0, 1)).to_array(),
                                 7, 7.5, transformer=tmp) for _ in range(args.popsize)]
            with make_executor(args.workers) as ex:
                map_episodes(ex, tasks[:ex.workers])  # warm the workers
                t = time.perf_counter()
                map_episodes(ex, tasks)
                wall = time.perf_counter() - t
            lines.append(f"one CMA-ES generation, population {args.popsize}, 7.5 s grounded episodes, {ex.workers} workers, "
                         f"lock-step batches: {wall:.1f} s")
            out.update(generation_s=wall, generation_popsize=args.popsize, generation_workers=ex.workers)
    out["text"] = "\n".join(lines)
    print(json.dumps(out) if args.json else out["text"], flush=True)
    return out


if __name__ == "__main__":
    main()
