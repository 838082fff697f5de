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


#: The timed pieces, in the order each repeat runs them.
BARE, UNGROUNDED, GROUNDED, CALL = ("bare mj_step (7500 steps)", "ungrounded walk", "grounded walk (SGAT)",
                                    "transformer call")


def build_parser() -> argparse.ArgumentParser:
    """The command line: repeats, the world, the optional generation (population, workers), ``--json``."""
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
    return ap


def time_bare_physics(sim) -> float:
    """Seconds of 7 500 ``mujoco.mj_step`` calls (7.5 s at 1 kHz) of ``sim`` holding the crouch."""
    import mujoco

    sim.reset(seed=0)
    sim.data.ctrl[:] = sim.robot.pose("crouch")
    t = time.perf_counter()
    mujoco.mj_step(sim.model, sim.data, nstep=7500)
    return time.perf_counter() - t


def time_walk(env, params) -> float:
    """Seconds of a 7.5 s walk of gait ``params`` (GaitParams) in ``env`` (seed 0)."""
    from experiments.runtime.fitness import run_walk

    t = time.perf_counter()
    run_walk(params, seed=0, seconds=7.5, env=env)
    return time.perf_counter() - t


def time_transformer_call(tr, sim, rng: np.random.Generator) -> float:
    """Seconds of one call of transformer ``tr`` (mean of 750, one episode's control steps) on a random
    state history (drawn from ``rng``) and the crouch's targets."""
    spec = tr.spec
    h = rng.normal(size=spec.history * spec.state_dim)
    a = sim.robot.pose("crouch", actuated=True)[spec.action_index]
    t = time.perf_counter()
    for _ in range(750):
        tr.transform(h, a)
    return (time.perf_counter() - t) / 750


def time_interleaved(sim, grounded, tr, rng: np.random.Generator, params, repeats: int) -> dict[str, list[float]]:
    """Each timed piece ``repeats`` times, interleaved: {piece (:data:`BARE`, ...): [seconds]}; progress
    on stderr."""
    res: dict[str, list[float]] = {BARE: [], UNGROUNDED: [], GROUNDED: [], CALL: []}
    for r in range(repeats):
        res[BARE].append(time_bare_physics(sim))
        res[UNGROUNDED].append(time_walk(sim, params))
        res[GROUNDED].append(time_walk(grounded, params))
        res[CALL].append(time_transformer_call(tr, sim, rng))
        print(f"[bench_grounding] repeat {r + 1}/{repeats} done", file=sys.stderr, flush=True)
    return res


def walk_report(res: dict[str, list[float]], repeats: int, world: str, tr) -> tuple[list[str], dict]:
    """The medians of :func:`time_interleaved`'s timings and their ratios: (the lines, {"repeats",
    "world", "members", "history", "median_s", "bare_s", the ratios, "transformer_call_us",
    "transformer_share_of_grounded"})."""
    spec = tr.spec
    med = {k: statistics.median(v) for k, v in res.items()}
    b = med[BARE]
    lines = [f"7.5 s episode, medians of {repeats} interleaved runs; transformer of the world {world} "
             f"({tr.n_members} member(s), history {spec.history}, "
             f"{'linear models' if not tr.forward.hidden else 'hidden ' + 'x'.join(map(str, tr.forward.hidden))})"]
    for k in (BARE, UNGROUNDED, GROUNDED):
        lines.append(f"  {k:28s} {med[k]:7.3f} s   {med[k] / b:5.2f} x bare")
    lines.append(f"  grounded / ungrounded walk     {med[GROUNDED] / med[UNGROUNDED]:.2f}")
    lines.append(f"  transformer call               {1e6 * med[CALL]:.1f} µs per control step "
                 f"({100 * 750 * med[CALL] / med[GROUNDED]:.1f} % of a grounded episode)")
    out = {"repeats": repeats, "world": world, "members": tr.n_members, "history": spec.history,
           "median_s": med, "bare_s": b, "ungrounded_over_bare": med[UNGROUNDED] / b,
           "grounded_over_bare": med[GROUNDED] / b,
           "grounded_over_ungrounded": med[GROUNDED] / med[UNGROUNDED],
           "transformer_call_us": 1e6 * med[CALL],
           "transformer_share_of_grounded": 750 * med[CALL] / med[GROUNDED]}
    return lines, out


def time_generation(tr, rng: np.random.Generator, params, popsize: int, workers: int | None) -> tuple[float, int]:
    """Seconds of one CMA-ES generation: ``popsize`` 7.5 s episodes (seed 7) of gaits drawn around
    ``params`` (normalized, σ 0.1, from ``rng``) in the sim grounded by ``tr``, in lock-step batches on
    a process pool of ``workers`` (warmed first): (seconds, the pool's workers)."""
    from experiments.runtime.batch import map_episodes
    from experiments.runtime.executors import make_executor
    from experiments.runtime.tasks import EpisodeTask
    from walk_engine import GaitParams

    print(f"[bench_grounding] one generation of {popsize} grounded episodes", file=sys.stderr, flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        tr.save(tmp)
        theta = params.to_vector()
        tasks = [EpisodeTask("sim", GaitParams.from_vector(np.clip(theta + 0.1 * rng.normal(size=16), 0, 1)).to_array(),
                             7, 7.5, transformer=tmp) for _ in range(popsize)]
        with make_executor(workers) as ex:
            map_episodes(ex, tasks[:ex.workers])  # warm the workers
            t = time.perf_counter()
            map_episodes(ex, tasks)
            wall = time.perf_counter() - t
    return wall, ex.workers


def main(argv=None) -> dict:
    """Parse the command line, time the pieces (and a generation with ``--generation``), print the lines
    (or JSON with ``--json``); returns the figures (:func:`walk_report`'s, ``generation_s``,
    ``generation_popsize``, ``generation_workers``, ``text``). Errors in the options exit through
    ``argparse`` (status 2)."""
    ap = build_parser()
    args = ap.parse_args(argv)
    if args.repeats < 1 or args.popsize < 1 or (args.workers is not None and args.workers < 1):
        ap.error("--repeats, --popsize and --workers must be >= 1")

    from envs import SimWorld
    from experiments.runtime.executors import limit_blas_threads
    from sgat.transformer import GroundedEnv  # loads torch before the thread limit
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
    p0 = GaitParams.initial()
    lines, out = walk_report(time_interleaved(sim, GroundedEnv(SimWorld(), tr), tr, rng, p0, args.repeats),
                             args.repeats, world, tr)
    if args.generation:
        wall, workers = time_generation(tr, rng, p0, args.popsize, args.workers)
        lines.append(f"one CMA-ES generation, population {args.popsize}, 7.5 s grounded episodes, {workers} workers, "
                     f"lock-step batches: {wall:.1f} s")
        out.update(generation_s=wall, generation_popsize=args.popsize, generation_workers=workers)
    out["text"] = "\n".join(lines)
    print(json.dumps(out) if args.json else out["text"], flush=True)
    return out


if __name__ == "__main__":
    main()
