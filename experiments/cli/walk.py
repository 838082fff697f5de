"""``sgatwalk walk``: run the ZMP walk engine with a gait parameter file in the sim, the real world, or
the identified sim (``--world identified --report REPORT_JSON``: the sim with the physics a diagnosis
found, uneven ground included).

Prints the forward speed [cm/s], whether the robot fell, the lateral drift and the paper's
fitness (speed - 15 if fallen); ``--record`` writes the rollout as a Parquet recording (with the
parameters in its metadata). Without ``--params`` the initial parameter set θ0 is used.
"""

from __future__ import annotations

import argparse
import time

from experiments.runtime.fitness import EPISODE_SECONDS, run_walk
from terrain import TERRAINS, check_amplitude, make
from walk_engine import WalkCommand, params_for
import experiments.cli.argtypes as A


def register(sub) -> argparse.ArgumentParser:
    p = sub.add_parser("walk", help="walk with a gait parameter file (ZMP engine) and report speed/fall/drift",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--params", type=A.in_file, metavar="JSON", help="gait parameters (16 names -> values); default: θ0")
    p.add_argument("--world", default="sim", choices=("sim", "real", "identified"),
                   help="sim (MuJoCo), real (PyBullet) or identified (the sim with the physics of --report)")
    p.add_argument("--report", type=A.in_path, nargs="+", metavar="REPORT_JSON",
                   help="with --world identified: report.json file(s) or folders of sgatwalk diagnose")
    p.add_argument("--confounded-terms", action="store_true",
                   help="with --world identified: also build in the contact terms the diagnosis could not tell apart "
                        "from the uneven ground (default off, as in sgatwalk fidelity and optimize)")
    p.add_argument("--seconds", type=A.seconds, default=EPISODE_SECONDS, help="episode length [s] (default 7.5)")
    p.add_argument("--seed", type=A.seed, default=0, help="episode seed (terrain, effects, noise)")
    p.add_argument("--profile", default=None, help="real-world effect profile: real (default), none, real-flat (real on flat ground) or real-ground (its uneven ground alone)")
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
    from robots import get_robot  # lazy: g1/talos parse their URDFs

    robot = get_robot(args.robot)
    P = params_for(robot)
    params = P.load(args.params) if args.params else P.initial()
    if args.world == "identified" and args.robot != "nao":
        raise ValueError("--world identified models the NAO only (sgatwalk diagnose identifies the NAO's physics)")
    if args.world != "real" and args.profile is not None:
        raise ValueError("--profile applies to the real world only (use --world real)")
    if args.confounded_terms and args.world != "identified":
        raise ValueError("--confounded-terms applies to --world identified only")
    if (args.world == "identified") != bool(args.report):
        raise ValueError("--world identified needs --report REPORT_JSON (and --report needs --world identified)")
    profile = args.profile or "real"
    terrain = None
    if args.amplitude is not None and args.terrain is None:
        raise ValueError("--amplitude needs --terrain (e.g. --terrain lumpy --amplitude 0.01)")
    if args.terrain is not None:
        amp = check_amplitude(args.terrain, 0.02 if args.amplitude is None else args.amplitude)
        terrain = "flat" if args.terrain == "flat" else make(args.terrain, seed=args.seed, amplitude=amp)
    command = WalkCommand(args.vx, args.vy, args.wz)
    env = None
    if args.world == "identified":
        from sysid.identified import IdentifiedSimEnv  # lazy: sysid; keeps sgatwalk --help fast

        env = IdentifiedSimEnv.from_reports(args.report, confounded=bool(args.confounded_terms),
                                            terrain=None if terrain in (None, "flat") else terrain)
    t0 = time.perf_counter()
    rec, res = run_walk(params, world=args.world, seed=args.seed, seconds=args.seconds, profile=profile,
                        terrain=terrain, command=command, env=env, robot=robot if env is None else None)
    wall = time.perf_counter() - t0
    out = {"robot": args.robot, "world": args.world, "seed": args.seed, **res.to_dict(),
           "profile": rec.meta.get("profile"),
           "terrain": rec.meta["terrain"]["name"] if rec.meta.get("terrain") else "flat",
           "params": params.to_dict(), "wall_s": wall}
    if args.record:
        out["recording"] = rec.to_parquet(args.record)
    if not args.json:
        print(format_walk(out))
    return out


def format_walk(out: dict) -> str:
    """The line ``sgatwalk walk`` prints, from its ``--json`` result."""
    fall = f"fell ({out['fall_reason']} at {out['fall_time_s']:.2f} s)" if out["fell"] else "did not fall"
    who = f"{out['robot']}, " if out.get("robot", "nao") != "nao" else ""
    return (f"{who}{out['world']} seed {out['seed']} [{out['terrain']}{', profile ' + out['profile'] if out['profile'] else ''}]: "
            f"speed {out['speed_cm_s']:.2f} cm/s, {fall}, drift {100 * out['drift_m']:.1f} cm, "
            f"distance {100 * out['distance_m']:.1f} cm, fitness {out['fitness']:.2f}"
            + (f"  -> {out['recording']}" if out.get("recording") else ""))
