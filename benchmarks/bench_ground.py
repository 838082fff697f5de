"""What does uneven ground cost the MuJoCo sim? A walk of θ0 on the plane, on a flat heightfield and on
the identified world's random ground, side by side.

The identified sim (``sysid.identified``, the base of the ``identified`` and ``hybrid`` training
worlds) walks on a Gaussian random surface of the RMS height the diagnosis fitted (about 3 mm;
``terrain.gaussian`` with its 8 cm correlation radius, 4 cm cells). MuJoCo collides a box with a
heightfield prism by prism and keeps up to ``mjMAXCONPAIR`` (50) contacts per geom pair (MuJoCo
documentation, XML reference, ``hfield``), where a box on a plane gets at most 4 (its corners); MJX
and MuJoCo Warp cull a heightfield pair to 4 contacts, the CPU engine does not. Each contact adds
rows (three with friction) to the constraint problem that every physics step solves.

Per ground, interleaved over ``--repeats`` repeats of ``--episodes`` walks of θ0 (7.5 s, the
episode seeds shared by every ground), the plain sim (``envs.SimWorld``, no grounding, no effects):

* contacts and constraint rows per control step (``MjData.ncon``, ``nefc``), means over the steps;
* MuJoCo's own timer of ``mj_step`` (``mjTIMER_STEP``) per physics step [µs], and the wall time of
  ``env.step`` per control step [µs] (10 physics steps, PD, sensors, fall check) with the walk engine;
* the ratio of each to the plane's (1.0 = as cheap as the plane).

The two heightfields are also walked with MuJoCo's sparse constraint Jacobian (``mjOption.jacobian``),
which the identified sim uses on its ground (``sysid.identified.GROUND_JACOBIAN``; the plain sim and
MuJoCo's ``auto`` use the dense one below 60 dofs): the same equations, stored without the zeros of
the many contact rows that touch one leg only.

Prints a table (medians over the repeats) or, with ``--json``, one JSON object (its ``"text"`` the
table); progress goes to stderr. Defaults (3 repeats of 4 walks on each of 5 grounds) take about
1.5 minutes on 2 idle cores.

Usage: ``python benchmarks/bench_ground.py [--episodes 4] [--repeats 3] [--rms 0.00285] [--json]``
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import gymnasium as gym  # noqa: E402
import mujoco  # noqa: E402

from envs import SimWorld  # noqa: E402
from experiments.runtime.fitness import run_walk  # noqa: E402
from sysid.identified import GROUND_JACOBIAN  # noqa: E402
from sysid.roughness import CORRELATION_RADIUS  # noqa: E402
from terrain import gaussian  # noqa: E402
from walk_engine import GaitParams  # noqa: E402


class _Counted(gym.Wrapper):
    """Counts contacts and constraint rows after every control step and times ``env.step``."""

    def __init__(self, env):
        super().__init__(env)
        self.steps = self.ncon = self.nefc = 0
        self.step_s = 0.0

    def step(self, action):
        t = time.perf_counter()
        out = self.env.step(action)
        self.step_s += time.perf_counter() - t
        d = self.env.unwrapped.data
        self.steps += 1
        self.ncon += int(d.ncon)
        self.nefc += int(d.nefc)
        return out


def measure(terrain, seeds: list[int], seconds: float, jacobian=None) -> dict:
    """Walk θ0 once per seed on ``terrain`` (None: the plane; a Heightfield: the same one every
    episode) in the plain sim, with MuJoCo's ``jacobian`` option (None: the sim's dense default);
    returns the per-step means and timings of the walks together."""
    env = _Counted(SimWorld(terrain=terrain))
    if jacobian is not None:
        env.unwrapped.model.opt.jacobian = jacobian  # a fixed terrain: the model is not rebuilt at reset
    falls, phys_us, phys_n = 0, 0.0, 0
    for s in seeds:
        _, res = run_walk(GaitParams(), seed=s, seconds=seconds, env=env)
        falls += bool(res.fell)
        tm = env.unwrapped.data.timer[int(mujoco.mjtTimer.mjTIMER_STEP)]  # reset with the episode's data
        phys_us += tm.duration * 1e6
        phys_n += tm.number
    return {"episodes": len(seeds), "falls": falls, "control_steps": env.steps,
            "contacts": env.ncon / env.steps, "constraint_rows": env.nefc / env.steps,
            "mj_step_us": phys_us / max(phys_n, 1), "env_step_us": 1e6 * env.step_s / env.steps}


def grounds(rms: float, seed: int) -> dict:
    """The grounds compared, name -> (terrain, MuJoCo jacobian option or None for the default): the
    sim's plane, a flat heightfield and the identified random ground, the last two also with the
    sparse Jacobian the identified sim builds on its ground (``sysid.identified.GROUND_JACOBIAN``)."""
    flat, rough = gaussian(seed, 0.0, CORRELATION_RADIUS), gaussian(seed, rms, CORRELATION_RADIUS)
    return {"plane": (None, None),
            "flat heightfield": (flat, None),
            f"random ground, Sq {1000 * rms:.2f} mm": (rough, None),
            "flat heightfield, sparse J": (flat, GROUND_JACOBIAN),
            "random ground, sparse J": (rough, GROUND_JACOBIAN)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 epilog="About 1.5 minutes at the defaults on 2 idle cores.")
    ap.add_argument("--episodes", type=int, default=4, help="walks per ground and repeat (default 4)")
    ap.add_argument("--repeats", type=int, default=3, help="interleaved repeats (default 3)")
    ap.add_argument("--rms", type=float, default=0.00285,
                    help="RMS height of the random ground [m] (default 0.00285: a diagnosis of Table I's seed 0)")
    ap.add_argument("--seconds", type=float, default=7.5, help="length of a walk [s] (default 7.5, the paper's)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the random ground and the episodes (default 0)")
    ap.add_argument("--json", action="store_true", help="print one JSON object (its \"text\": the table)")
    args = ap.parse_args(argv)
    if args.episodes < 1 or args.repeats < 1 or not args.rms > 0 or not args.seconds > 0:
        ap.error("--episodes and --repeats must be >= 1, --rms and --seconds > 0")
    gs = grounds(args.rms, args.seed)
    seeds = [args.seed + i for i in range(args.episodes)]
    runs: dict[str, list[dict]] = {k: [] for k in gs}
    for r in range(args.repeats):
        for name, (terrain, jacobian) in gs.items():
            runs[name].append(measure(terrain, seeds, args.seconds, jacobian))
            print(f"[bench_ground] repeat {r + 1}/{args.repeats}: {name} done", file=sys.stderr, flush=True)
    out = {"episodes": args.episodes, "repeats": args.repeats, "rms_height": args.rms, "seconds": args.seconds,
           "grounds": {}}
    base = None
    for name, rs in runs.items():
        med = {k: statistics.median(x[k] for x in rs) for k in ("contacts", "constraint_rows", "mj_step_us", "env_step_us")}
        base = base or med
        out["grounds"][name] = {**med, "falls": rs[0]["falls"], "episodes": rs[0]["episodes"],
                                "mj_step_ratio": med["mj_step_us"] / base["mj_step_us"],
                                "env_step_ratio": med["env_step_us"] / base["env_step_us"]}
    head = (f"{'ground':28s} {'falls':>7s} {'contacts':>8s} {'rows':>6s} {'mj_step [us]':>12s} {'x plane':>7s} "
            f"{'env.step [us]':>13s} {'x plane':>7s}")
    lines = [head, "-" * len(head)]
    for name, g in out["grounds"].items():
        lines.append(f"{name:28s} {g['falls']:>3d}/{g['episodes']:<3d} {g['contacts']:8.1f} {g['constraint_rows']:6.0f} "
                     f"{g['mj_step_us']:12.0f} {g['mj_step_ratio']:7.2f} {g['env_step_us']:13.0f} {g['env_step_ratio']:7.2f}")
    lines.append(f"medians of {args.repeats} interleaved repeats of {args.episodes} walks of θ0 ({args.seconds:g} s) per ground; "
                 "x plane: the ratio to the plane's median")
    out["text"] = "\n".join(lines)
    print(json.dumps(out) if args.json else out["text"], flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
