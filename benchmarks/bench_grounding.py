"""Cost of grounding: a grounded walk vs an ungrounded one vs bare ``mj_step``, side by side.

Times, interleaved and repeated (medians):

* bare ``mujoco.mj_step`` for the physics of a 7.5 s episode (7 500 steps at 1 kHz);
* an ungrounded θ0 walk in the sim (walk engine + env + recording);
* the same walk in ``sgat.GroundedEnv`` with an SGAT transformer (2x64 MLPs, NumPy inference),
  and the transformer call alone per control step.

Then one CMA-ES generation at population 150 with 7.5 s grounded episodes through the default
process pool (``--generation``; about a minute on 2 cores).

``--save NAME`` also writes ``docs/results/NAME.json`` for the README (medians, ratios, the printed
lines, the load average).

Usage: ``python benchmarks/bench_grounding.py [--repeats 5] [--generation] [--save benchgrounding]``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time

import numpy as np


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--generation", action="store_true", help="also time one CMA-ES generation at population 150")
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--save", metavar="NAME", help="also write docs/results/NAME.json (for the README)")
    args = ap.parse_args(argv)
    load_before = os.getloadavg()[0]

    import mujoco

    from envs import NaoSimEnv
    from experiments.runtime.fitness import run_walk
    from sgat.models import ForwardModel, InverseModel
    from experiments.runtime.grounding import grounding_spec
    from sgat.transformer import ActionTransformer, GroundedEnv
    from walk_engine import GaitParams

    sim = NaoSimEnv()
    spec = grounding_spec(sim)
    rng = np.random.default_rng(0)
    # a transformer with random-but-fitted weights (fit on synthetic data: the cost is what matters)
    fwd, inv = ForwardModel(spec.state_dim, spec.action_dim), InverseModel(spec.state_dim, spec.action_dim)
    X = rng.normal(size=(400, spec.state_dim + spec.action_dim))
    fwd.fit(X, rng.normal(size=(400, spec.state_dim)) * 1e-3, max_epochs=2)
    inv.fit(rng.normal(size=(400, 2 * spec.state_dim)), sim.robot.pose("crouch", actuated=True)[spec.action_index]
            + rng.normal(size=(400, spec.action_dim)) * 1e-3, max_epochs=2)
    tr = ActionTransformer(spec, fwd, inv, method="sgat", alpha=0.5)
    grounded = GroundedEnv(NaoSimEnv(), tr)
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
        h, a = rng.normal(size=spec.state_dim), sim.robot.pose("crouch", actuated=True)[spec.action_index]
        t = time.perf_counter()
        for _ in range(750):
            tr.transform(h, a)
        return (time.perf_counter() - t) / 750

    res = {"bare mj_step (7500 steps)": [], "ungrounded walk": [], "grounded walk (SGAT)": [], "transformer call": []}
    for _ in range(args.repeats):
        res["bare mj_step (7500 steps)"].append(bare())
        res["ungrounded walk"].append(walk(sim))
        res["grounded walk (SGAT)"].append(walk(grounded))
        res["transformer call"].append(transform())
    med = {k: statistics.median(v) for k, v in res.items()}
    b = med["bare mj_step (7500 steps)"]
    lines = [f"7.5 s episode, medians of {args.repeats} interleaved runs"]
    for k in ("bare mj_step (7500 steps)", "ungrounded walk", "grounded walk (SGAT)"):
        lines.append(f"  {k:28s} {med[k]:7.3f} s   {med[k] / b:5.2f} x bare")
    lines.append(f"  grounded / ungrounded walk     {med['grounded walk (SGAT)'] / med['ungrounded walk']:.2f}")
    lines.append(f"  transformer call               {1e6 * med['transformer call']:.1f} µs per control step "
                 f"({100 * 750 * med['transformer call'] / med['grounded walk (SGAT)']:.1f} % of a grounded episode)")
    print("\n".join(lines), flush=True)
    out = {"repeats": args.repeats, "median_s": med,
           "bare_s": b, "ungrounded_over_bare": med["ungrounded walk"] / b,
           "grounded_over_bare": med["grounded walk (SGAT)"] / b,
           "grounded_over_ungrounded": med["grounded walk (SGAT)"] / med["ungrounded walk"],
           "transformer_call_us": 1e6 * med["transformer call"],
           "transformer_share_of_grounded": 750 * med["transformer call"] / med["grounded walk (SGAT)"]}

    if args.generation:
        from experiments.runtime.executors import make_executor
        from experiments.runtime.tasks import run_episode

        with tempfile.TemporaryDirectory() as tmp:
            tr.save(tmp)
            theta = p0.to_vector()
            tasks = [{"world": "grounded", "transformer": tmp, "seed": 7, "seconds": 7.5,
                      "theta": GaitParams.from_vector(np.clip(theta + 0.1 * rng.normal(size=16), 0, 1)).to_array().tolist()}
                     for _ in range(150)]
            with make_executor(args.workers) as ex:
                ex.map(run_episode, tasks[:ex.workers])  # warm the workers
                t = time.perf_counter()
                ex.map(run_episode, tasks)
                wall = time.perf_counter() - t
            lines.append(f"one CMA-ES generation, population 150, 7.5 s grounded episodes, {ex.workers} workers: {wall:.1f} s")
            print(lines[-1])
            out.update(generation_s=wall, generation_workers=ex.workers)
    out["text"] = "\n".join(lines)
    if args.save:
        from tools.readme import save_benchmark

        save_benchmark(args.save, "benchmarks/bench_grounding.py", sys.argv[1:] if argv is None else list(argv), out,
                       load_before)
    return out


if __name__ == "__main__":
    main()
