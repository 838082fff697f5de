"""What does a hybrid optimization spend besides the physics? Each piece done apart (per episode, per
member) against together (for the batch, on a pool), side by side in one run.

Two pieces of ``sgatwalk optimize``'s default (hybrid) run that are bookkeeping, not simulation:

* **The fall check's ground lookup.** Every control step, a lock-step batch (``envs.batch.SimBatch``)
  asks the ground height under each episode's torso; in the identified sim every episode walks its own
  random surface. Timed for ``--episodes`` episodes (a worker's share of a 12-candidate generation on 2
  cores: 6) on their own surfaces (``terrain.gaussian``, the identified sim's correlation radius, 4 cm
  cells), over ``--steps`` control steps of torso positions within the surfaces and beyond their
  edges: one :func:`envs.base.ground_height` call per episode (apart) against one
  :class:`envs.base.GroundStack` call for the batch (the fields stacked once per batch). The heights
  must agree bit for bit.
* **The grounding fit's ensemble.** A grounding step fits the ensemble of the world ``sgat`` (5
  forward/inverse pairs at its defaults, its history and models) on its real and sim walks of θ0 (the
  first grounding step's data: the real world against the sim with the world's exploration noise);
  timed fitted one after another in this process (apart) against one
  member per worker of a warm process pool of ``--workers`` (``fit_grounding``'s ``map_fn``, what
  ``optimize`` passes: together). Every weight must agree bit for bit.

Interleaved over ``--repeats`` repeats; medians and their ratios (apart / together: above 1, together is
faster). Prints a table or, with ``--json``, one JSON object (its ``"text"`` the table); progress goes
to stderr. Exits 1 unless both ways agree bit for bit. Defaults (3 repeats) take about 1.5 minutes
on 2 idle cores.

Usage: ``python benchmarks/bench_overhead.py [--episodes 6] [--steps 750] [--repeats 3] [--workers 2] [--json]``
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402


def lookup_times(fields, xs, ys) -> dict:
    """The fall check's lookups over every step, both ways. Returns seconds per control step and whether
    the heights agree."""
    from envs.base import GroundStack, ground_height

    B = len(fields)
    ep = np.arange(B)
    t0 = time.perf_counter()
    apart = np.array([[float(ground_height(fields[i], xs[k, i], ys[k, i])) for i in range(B)] for k in range(len(xs))])
    t_apart = time.perf_counter() - t0
    t0 = time.perf_counter()
    stack = GroundStack(fields)  # once per batch, at its reset
    together = np.array([stack.height(ep, xs[k], ys[k]) for k in range(len(xs))])
    t_together = time.perf_counter() - t0
    return {"apart_s": t_apart / len(xs), "together_s": t_together / len(xs), "same": bool(np.array_equal(apart, together))}


#: The training world whose grounding data and ensemble are timed.
WORLD = "sgat"


def grounding_data(seconds: float):
    """The real walks of θ0 and the sim walks with the exploration noise of the world :data:`WORLD`
    (the first grounding step's data; seeds of this benchmark's own, 100+ and 200+), recorded on a
    pool of 2."""
    from envs import Recording
    from experiments.runtime.batch import map_episodes
    from experiments.runtime.executors import ProcessExecutor
    from experiments.runtime.tasks import EpisodeTask
    from experiments.runtime.worlds import parse_world
    from walk_engine import GaitParams

    spec = parse_world(WORLD)
    n_real = int(spec.get("real"))
    theta = GaitParams().to_array()
    tasks = ([EpisodeTask("real", theta, 100 + i, seconds, record=True) for i in range(n_real)]
             + [EpisodeTask("sim", theta, 200 + i, seconds, record=True, action_noise=float(spec.get("explore")))
                for i in range(int(spec.get("sim")))])
    with ProcessExecutor(2) as ex:
        res = map_episodes(ex, tasks)
    recs = [Recording(*r.recording) for r in res]
    return recs[:n_real], recs[n_real:]


def fit_times(real, sim, ex) -> dict:
    """The grounding fit, both ways. Returns seconds and whether every weight agrees."""
    import torch

    from experiments.runtime.grounding import fit_walk_grounding
    from experiments.runtime.worlds import parse_world

    spec = parse_world(WORLD)
    cfg, history = spec.grounding_config(), int(spec.get("history"))

    def weights(fit):
        tr = fit.transformer
        return [p for m in list(tr.forwards) + list(tr.inverses) for p in m.state_dict().values()]

    t0 = time.perf_counter()
    a = fit_walk_grounding(real, sim, cfg, history=history, seed=1)
    t_apart = time.perf_counter() - t0
    t0 = time.perf_counter()
    b = fit_walk_grounding(real, sim, cfg, history=history, seed=1, map_fn=ex.map)
    t_together = time.perf_counter() - t0
    wa, wb = weights(a), weights(b)
    same = len(wa) == len(wb) and all(torch.equal(x, y) for x, y in zip(wa, wb))
    return {"apart_s": t_apart, "together_s": t_together, "same": bool(same), "members": a.transformer.n_members}


def _warm(_):
    return os.getpid()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 epilog="About 1.5 minutes at the defaults on 2 idle cores. Exits 1 unless both ways "
                                        "agree bit for bit.")
    ap.add_argument("--episodes", type=int, default=6, help="episodes of one batch (default 6)")
    ap.add_argument("--steps", type=int, default=750, help="control steps of the lookup (default 750: 7.5 s)")
    ap.add_argument("--repeats", type=int, default=3, help="interleaved repeats (default 3)")
    ap.add_argument("--workers", type=int, default=2, help="process pool of the ensemble fit (default 2)")
    ap.add_argument("--rms", type=float, default=0.00285, help="RMS height of the random surfaces [m] (default 0.00285)")
    ap.add_argument("--seconds", type=float, default=7.5, help="length of the grounding walks [s] (default 7.5)")
    ap.add_argument("--json", action="store_true", help="print one JSON object (its \"text\": the table)")
    args = ap.parse_args(argv)
    if min(args.episodes, args.steps, args.repeats, args.workers) < 1 or not args.rms > 0 or not args.seconds > 0:
        ap.error("--episodes, --steps, --repeats and --workers must be >= 1, --rms and --seconds > 0")
    from experiments.runtime.executors import ProcessExecutor, limit_blas_threads
    from sysid.roughness import CORRELATION_RADIUS
    from terrain import gaussian

    limit_blas_threads()  # one BLAS thread, as optimize's workers, also where numpy was loaded before

    rng = np.random.default_rng(0)
    fields = [gaussian(np.random.default_rng(s), args.rms, CORRELATION_RADIUS) for s in range(args.episodes)]
    hx, hy = fields[0].half_extent
    # torso paths: walks from the origin, some past the fields' edges (the lookup clips to the edge)
    xs = np.cumsum(rng.normal(0.0, 0.01, (args.steps, args.episodes)), axis=0) * (1.5 * hx / 0.3)
    ys = np.cumsum(rng.normal(0.0, 0.01, (args.steps, args.episodes)), axis=0) * (1.5 * hy / 0.3)
    print(f"[bench_overhead] recording the grounding walks of θ0 of the world {WORLD}", file=sys.stderr, flush=True)
    real, sim = grounding_data(args.seconds)
    look, fits = [], []
    with ProcessExecutor(args.workers) as ex:
        ex.map(_warm, range(args.workers))  # a warm pool, as optimize's is by its first fit
        for r in range(args.repeats):
            look.append(lookup_times(fields, xs, ys))
            fits.append(fit_times(real, sim, ex))
            print(f"[bench_overhead] repeat {r + 1}/{args.repeats} done", file=sys.stderr, flush=True)
    med = lambda rs, k: statistics.median(x[k] for x in rs)  # noqa: E731
    out = {"episodes": args.episodes, "steps": args.steps, "repeats": args.repeats, "workers": args.workers,
           "rms_height": args.rms, "world": WORLD, "grounding_walks": [len(real), len(sim)],
           "lookup": {"apart_us_per_step": 1e6 * med(look, "apart_s"), "together_us_per_step": 1e6 * med(look, "together_s"),
                      "ratio": med(look, "apart_s") / med(look, "together_s"), "bit_identical": all(x["same"] for x in look)},
           "ensemble_fit": {"members": fits[0]["members"], "apart_s": med(fits, "apart_s"), "together_s": med(fits, "together_s"),
                            "ratio": med(fits, "apart_s") / med(fits, "together_s"), "bit_identical": all(x["same"] for x in fits)}}
    lk, ft = out["lookup"], out["ensemble_fit"]
    lookup_name = f"fall-check ground lookup, {args.episodes} episodes [us/step]"
    fit_name = f"ensemble fit, {ft['members']} members, {args.workers} workers [s]"
    out["text"] = "\n".join([
        f"medians of {args.repeats} interleaved repeats; apart / together: above 1, together is faster",
        f"{'piece':44s} {'apart':>10s} {'together':>10s} {'ratio':>8s} {'bit-identical':>13s}",
        f"{lookup_name:44s} {lk['apart_us_per_step']:10.0f} "
        f"{lk['together_us_per_step']:10.0f} {lk['ratio']:8.1f} {str(lk['bit_identical']).lower():>13s}",
        f"{fit_name:44s} {ft['apart_s']:10.1f} {ft['together_s']:10.1f} "
        f"{ft['ratio']:8.2f} {str(ft['bit_identical']).lower():>13s}",
    ])
    print(json.dumps(out) if args.json else out["text"], flush=True)
    return 0 if lk["bit_identical"] and ft["bit_identical"] else 1


if __name__ == "__main__":
    sys.exit(main())
