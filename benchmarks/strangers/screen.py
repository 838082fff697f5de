"""Stability screen of the strangers' world over its draw ranges (prints a table; no files).

For every effect kind, the effect at both corners of its draw range (:func:`.effects.corner_effect`)
on every eligible target at once, in three excitations: a hanging robot under a 6 s chirp of 0.3 rad
to 6 Hz on all joints (fixed-base kinds), a robot standing under a 4 s leg chirp of 0.02 rad to 2 Hz, and a
walk of the default gait for 5 s (floating-base kinds and the actuator kinds too). A run is "unstable"
if the episode ends with the fall reason ``unstable`` (a joint faster than 200 rad/s or a non-finite
state); the table gives the largest joint speed [rad/s] against the no-effect run, and falls.

Usage::

    python -m benchmarks.strangers.screen [--kinds K1,K2] [--seconds 6]
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from envs.excitation import chirp_with_holds
from envs.rollout import CommandLog, rollout
from robots import nao_h25

from .effects import KINDS, corner_effect
from .world import make_world


def _run(hidden, fixed_base: bool, mode: str, seconds: float, robot) -> tuple[float, str | None]:
    env = make_world(hidden, fixed_base=fixed_base, noise=0.0)
    if mode == "walk":
        from walk_engine import WalkEngine

        ctrl = WalkEngine(robot)
    elif fixed_base:
        ctrl = CommandLog(chirp_with_holds(robot, seconds=seconds, hold=0.5, amplitude=0.3, f1=6.0))
    else:
        ctrl = CommandLog(chirp_with_holds(robot, seconds=seconds, hold=0.5, amplitude=0.02, f1=2.0,
                                           joints=list(robot.groups["legs"])))
    rec = rollout(env, ctrl, seed=1, seconds=seconds)
    env.close()
    dq = np.abs(rec.group("dq"))
    return float(np.nanmax(dq)), rec.meta.get("fall_reason")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kinds", default=",".join(KINDS))
    ap.add_argument("--seconds", type=float, default=6.0)
    ap.add_argument("--modes", default="fixed,stand,walk")
    a = ap.parse_args(argv)
    robot = nao_h25()
    modes = a.modes.split(",")
    base = {}
    for m in modes:
        base[m] = _run([], m == "fixed", m, a.seconds if m == "fixed" else 4.0, robot)
    print(f"{'none':26s}", "  ".join(f"{m}: dq {base[m][0]:6.1f} {base[m][1]}" for m in modes), flush=True)
    bad = 0
    for kind in a.kinds.split(","):
        spec = KINDS[kind]
        for corner in ("low", "high"):
            cells = []
            t0 = time.perf_counter()
            for m in modes:
                if m == "fixed" and spec.floating_only:
                    cells.append(f"{m}: --")
                    continue
                secs = a.seconds if m == "fixed" else (5.0 if m == "walk" else 4.0)
                top, reason = _run([corner_effect(kind, robot, corner)], m == "fixed", m, secs, robot)
                bad += reason == "unstable"
                cells.append(f"{m}: dq {top:6.1f} {reason}")
            print(f"{kind + ' ' + corner:26s}", "  ".join(cells), f"({time.perf_counter() - t0:.0f} s)", flush=True)
    print("unstable runs:", bad)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
