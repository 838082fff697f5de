"""``sgatwalk stand``: hold the walking crouch in the sim and/or the real world and report.

The demo of the two worlds: the robot stands in a pose for ``--seconds`` on flat ground or on a
heightfield; the command prints, per world, whether it fell, how far its CoM drifted, the mean
foot forces and the simulation speed, and can write each rollout as a Parquet recording.
"""

from __future__ import annotations

import argparse
from terrain import TERRAINS
import experiments.cli.argtypes as A


def register(sub) -> argparse.ArgumentParser:
    p = sub.add_parser("stand", help="hold a pose in the sim and/or real world (demo of the two worlds)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--world", default="sim,real", help="sim, real or sim,real (default: both)")
    p.add_argument("--pose", default="crouch", help="robot pose to hold (zero, stand, crouch; the NAO also deep_crouch)")
    p.add_argument("--seconds", type=A.seconds, default=10.0, help="duration [s] (default 10)")
    p.add_argument("--seed", type=A.seed, default=0, help="episode seed (terrain, effects, noise)")
    A.add_profile(p)
    p.add_argument("--terrain", default=None, choices=TERRAINS,
                   help="terrain for both worlds (default: flat sim, the profile's random lumpy field in real)")
    p.add_argument("--amplitude", type=A.real(0.0, 1.0), default=None,
                   help="terrain amplitude with --terrain: bump/step height [m], slope grade, gaussian RMS height [m] "
                        "(default 0.01)")
    p.add_argument("--fixed-base", action="store_true", help="hang the robot in the air (actuator tests)")
    A.add_robot(p)
    p.add_argument("--record", type=A.out_file, metavar="PATH", help="write recordings; '{world}' in PATH is replaced "
                   "(default PATH for two worlds: PATH with _sim/_real before the suffix)")
    return p


def run(args) -> dict:
    from experiments.demos.stand import StandConfig, format_stand, stand

    with A.user_input():
        cfg = StandConfig(worlds=tuple(w.strip() for w in args.world.split(",") if w.strip()), pose=args.pose,
                          seconds=args.seconds, seed=args.seed, profile=args.profile or "real", terrain=args.terrain,
                          amplitude=args.amplitude, fixed_base=args.fixed_base, robot=args.robot, record=args.record,
                          stochasticity=args.stochasticity)
    res = stand(cfg)
    if not args.json:
        print(format_stand(res["worlds"]))
    return res
