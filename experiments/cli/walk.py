"""``sgatwalk walk``: run the ZMP walk engine with a gait parameter file in the sim, the real world, or
the identified sim (``--world identified --report REPORT_JSON``: the sim with the physics a diagnosis
found, uneven ground included).

Prints the forward speed [cm/s], whether the robot fell, the lateral drift and the paper's
fitness (speed - 15 if fallen); ``--record`` writes the rollout as a Parquet recording (with the
parameters in its metadata). Without ``--params`` the initial parameter set θ0 is used.
"""

from __future__ import annotations

import argparse

from common.defaults import EPISODE_SECONDS
from terrain import TERRAINS
import experiments.cli.argtypes as A


def register(sub) -> argparse.ArgumentParser:
    p = sub.add_parser("walk", help="walk with a gait parameter file (ZMP engine) and report speed/fall/drift",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--params", type=A.in_file, metavar="JSON", help="gait parameters (16 names -> values); default: θ0")
    p.add_argument("--world", default="sim", choices=("sim", "real", "identified"),
                   help="sim (MuJoCo), real (PyBullet) or identified (the sim with the physics of --report)")
    p.add_argument("--report", type=A.in_path, nargs="+", metavar="REPORT_JSON",
                   help="with --world identified: report.json file(s) or folders of sgatwalk diagnose")
    p.add_argument("--seconds", type=A.seconds, default=EPISODE_SECONDS, help="episode length [s] (default 7.5)")
    p.add_argument("--seed", type=A.seed, default=0, help="episode seed (terrain, effects, noise)")
    A.add_profile(p)
    p.add_argument("--terrain", default=None, choices=TERRAINS,
                   help="terrain (default: flat in the sim, the profile's random lumpy field in the real world)")
    p.add_argument("--amplitude", type=A.real(0.0, 1.0), default=None,
                   help="terrain amplitude with --terrain: bump/step height [m], slope grade, gaussian RMS height [m] "
                        "(default 0.02)")
    p.add_argument("--vx", type=A.real(-1.0, 1.0, unit='m/s'), default=None, help="forward speed command [m/s] (default: the gait's own)")
    p.add_argument("--vy", type=A.real(-0.5, 0.5, unit='m/s'), default=0.0, help="sideways speed command [m/s], + left")
    p.add_argument("--wz", type=A.real(-2.0, 2.0, unit='rad/s'), default=0.0, help="turn rate command [rad/s], + left")
    p.add_argument("--record", type=A.out_file, metavar="PATH", help="write the rollout as a Parquet recording")
    A.add_robot(p)
    return p


def run(args) -> dict:
    from experiments.demos.walk import WalkConfig, format_walk, walk

    with A.user_input():
        cfg = WalkConfig(params=args.params, world=args.world, report=tuple(args.report or ()), seconds=args.seconds,
                         seed=args.seed, profile=args.profile, terrain=args.terrain, amplitude=args.amplitude, vx=args.vx,
                         vy=args.vy, wz=args.wz, robot=args.robot, record=args.record, stochasticity=args.stochasticity)
        gait, identified = cfg.gait(), cfg.identified_terms()
    res = walk(cfg, gait, identified)
    if not args.json:
        print(format_walk(res))
    return res
