"""``sgatwalk excite``: record the system-identification excitation protocol in a world.

Runs :func:`sysid.excitation.protocol` (posture holds, slow ramps, target steps, load reversals,
a gait-like pattern and a 0.3-4 Hz chirp; for a floating base: legs pushed apart and pulled
together in double support so the feet slide on a slippery floor, then stepping and weight shifts) for
``--logs`` trajectories and writes one Parquet recording per trajectory into ``--out``. In the
real world the profile's effects are drawn once (from ``--seed``) and kept for every log, like one
physical robot; sensor noise differs per log. ``--robot`` picks the robot (NAO, Unitree G1, PAL
Talos); the recordings name it (``meta["robot"]``), and ``sgatwalk diagnose --real OUT`` reads the
folder and replays that robot.
"""

from __future__ import annotations

import argparse
import time

import experiments.argtypes as A


def register(sub) -> argparse.ArgumentParser:
    p = sub.add_parser("excite", help="record system-identification excitation logs (for sgatwalk diagnose)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--world", default="real", choices=("real", "sim"), help="world to record in (default real)")
    A.add_robot(p)
    p.add_argument("--profile", default="real", help="real-world effect profile: real (default; scaled to the "
                   "robot's actuators) or none")
    p.add_argument("--effect", action="append", default=[], metavar="NAME=VALUE",
                   help="override one profile effect with a fixed value, e.g. latency_s=0.02 (repeatable)")
    p.add_argument("--fixed-base", action="store_true", help="hang the robot in the air (actuator tests; recommended first)")
    p.add_argument("--terrain", default="flat", choices=("flat", "lumpy"),
                   help="real-world ground for floating-base logs (default flat); lumpy: a fresh field of random "
                        "bumps per log under the feet (no flat start pad), peak height from the profile's "
                        "terrain_amplitude (e.g. --effect terrain_amplitude=0.01)")
    p.add_argument("--out", type=A.out_dir, required=True, metavar="DIR", help="folder for the recordings")
    p.add_argument("--logs", type=A.count(1, 1000), default=4, help="number of trajectories (default 4; >= 2 for a held-out split)")
    p.add_argument("--seconds", type=A.real(3.0, 3600.0, unit="s"), default=8.0, help="duration of each log [s] (default 8)")
    p.add_argument("--seed", type=A.seed, default=0, help="seed of the robot's effects and of the trajectories")
    p.add_argument("--scale", type=A.real(0.0, 3.0, open_lo=True), default=1.0, help="amplitude scale of the motions (default 1)")
    return p


def run(args) -> dict:
    from envs import make_world  # lazy: loads the engines; keeps sgatwalk --help fast
    from envs.effects import get_profile  # lazy: loads the engines; keeps sgatwalk --help fast
    from sysid.worlds import freeze, record_excitation, rough_ground  # lazy: loads the engines; keeps sgatwalk --help fast
    from robots import get_robot  # lazy: g1/talos parse their URDFs

    robot = get_robot(args.robot)
    kw = {"fixed_base": args.fixed_base, "robot": robot}
    ground = None
    if args.world == "real":
        prof = get_profile(args.profile, robot)
        for item in args.effect:
            if "=" not in item:
                raise ValueError(f"--effect expects NAME=VALUE, got {item!r}")
            name, val = item.split("=", 1)
            try:
                prof = prof.with_effect(name.strip(), float(val))
            except ValueError as exc:
                raise ValueError(f"--effect {item}: {exc}") from None
        frozen = freeze(prof, args.seed, robot)
        kw.update(profile=frozen, terrain="flat")
        if args.terrain == "lumpy":
            if args.fixed_base:
                raise ValueError("--terrain lumpy needs a floating base (omit --fixed-base)")
            ground = rough_ground(float(frozen.frozen.terrain_amplitude), seed=args.seed)
    elif args.effect or args.terrain != "flat":
        raise ValueError("--effect and --terrain apply to the real world only")
    env = make_world(args.world, **kw)
    t0 = time.perf_counter()
    say = None if args.json else print
    paths = record_excitation(env, args.out, n_logs=args.logs, seconds=args.seconds, seed=args.seed,
                              scale=args.scale, progress=say, terrain=ground)
    env.close()
    wall = time.perf_counter() - t0
    if not args.json:
        print(f"wrote {len(paths)} log(s) of {args.seconds:g} s to {args.out} in {wall:.1f} s; "
              f"next: sgatwalk diagnose --real {args.out} --out REPORT_DIR")
    return {"robot": robot.name, "world": args.world, "profile": args.profile if args.world == "real" else None,
            "fixed_base": args.fixed_base, "recordings": paths, "wall_s": wall}
