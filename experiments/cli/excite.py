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
import sys
import time

import experiments.cli.argtypes as A


def register(sub) -> argparse.ArgumentParser:
    p = sub.add_parser("excite", help="record system-identification excitation logs (for sgatwalk diagnose)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--world", default="real", choices=("real", "sim"), help="world to record in (default real)")
    A.add_robot(p)
    p.add_argument("--profile", default="real", help="real-world effect profile: real (default; scaled to the "
                   "robot's actuators), none, real-flat (real on flat ground) or real-ground (its uneven ground alone)")
    p.add_argument("--effect", action="append", default=[], metavar="NAME=VALUE",
                   help="override one profile effect with a fixed value, e.g. latency_s=0.02 (repeatable)")
    p.add_argument("--fixed-base", action="store_true", help="hang the robot in the air (actuator tests; recommended first)")
    p.add_argument("--terrain", default="flat", choices=("flat", "lumpy"),
                   help="real-world ground for floating-base logs (default flat); lumpy: a fresh field of random "
                        "bumps per log under the feet (no flat start pad), peak height from the profile's "
                        "terrain_amplitude (e.g. --effect terrain_amplitude=0.01)")
    p.add_argument("--out", type=A.out_dir, metavar="DIR", help="folder for the recordings (required unless --design-only)")
    p.add_argument("--logs", type=A.count(1, 1000), default=4, help="number of trajectories (default 4; >= 2 for a held-out split)")
    p.add_argument("--seconds", type=A.real(3.0, 3600.0, unit="s"), default=8.0, help="duration of each log [s] (default 8)")
    p.add_argument("--seed", type=A.seed, default=0, help="seed of the robot's effects and of the trajectories")
    p.add_argument("--scale", type=A.real(0.0, 3.0, open_lo=True), default=1.0, help="amplitude scale of the motions (default 1)")
    p.add_argument("--segments", type=_segments, metavar="LIST",
                   help="comma list of protocol segments, in order (default holds,ramps,steps,reversals,gait,chirp); "
                        "'+saturation' adds steps that drive every joint into its torque limit (fixed base)")
    p.add_argument("--design", choices=("protocol", "d-optimal"), default="protocol",
                   help="segment shares: the protocol's own (default) or D-optimal: chosen on the sim, before "
                        "anything is recorded, to maximise the Fisher information of the candidate families "
                        "(fixed base; prints each family's expected identifiability under both; ~1 min)")
    p.add_argument("--design-only", action="store_true", help="print the design and record nothing (no --out needed)")
    return p


def _segments(text: str) -> tuple[str, ...]:
    """``--segments``: a comma list of segment names, or ``+NAME,...`` to add to the default protocol."""
    from sysid.excitation import KNOWN_SEGMENTS, OPTIONAL_SEGMENTS, SEGMENTS

    add = text.startswith("+")
    names = [s.strip() for s in text.lstrip("+").split(",") if s.strip()]
    bad = [s for s in names if s not in KNOWN_SEGMENTS]
    if not names or bad:
        raise argparse.ArgumentTypeError(f"unknown segment(s) {', '.join(bad) or repr(text)}; known: "
                                         f"{', '.join(SEGMENTS + OPTIONAL_SEGMENTS)}")
    return tuple(SEGMENTS) + tuple(s for s in names if s not in SEGMENTS) if add else tuple(names)


def run(args) -> dict:
    from envs import make_world  # lazy: loads the engines; keeps sgatwalk --help fast
    from envs.effects import get_profile  # lazy: loads the engines; keeps sgatwalk --help fast
    from sysid.worlds import freeze, record_excitation, rough_ground  # lazy: loads the engines; keeps sgatwalk --help fast
    from robots import get_robot  # lazy: g1/talos parse their URDFs

    with A.user_input():
        if args.segments and "saturation" in args.segments and not args.fixed_base:
            raise ValueError("--segments saturation needs --fixed-base (a standing robot would fall)")
        if (args.design != "protocol" or args.design_only) and not args.fixed_base:
            raise ValueError("--design d-optimal needs --fixed-base (the design replays the robot in the air)")
        if args.design_only and args.design == "protocol":
            raise ValueError("--design-only needs --design d-optimal")
        if args.out is None and not args.design_only:
            raise ValueError("--out DIR is required (the folder for the recordings)")
        if args.world != "real" and (args.effect or args.terrain != "flat"):
            raise ValueError("--effect and --terrain apply to the real world only")
        if args.terrain == "lumpy" and args.fixed_base:
            raise ValueError("--terrain lumpy needs a floating base (omit --fixed-base)")
        robot = get_robot(args.robot)
        prof = get_profile(args.profile, robot) if args.world == "real" else None
        for item in args.effect if args.world == "real" else ():
            if "=" not in item:
                raise ValueError(f"--effect expects NAME=VALUE, got {item!r}")
            name, val = item.split("=", 1)
            try:
                prof = prof.with_effect(name.strip(), float(val))
            except ValueError as exc:
                raise ValueError(f"--effect {item}: {exc}") from None
    shares = None
    plan = None
    if args.design == "d-optimal":
        from sysid.design import design, format_design  # lazy: replays the sim
        from sysid.excitation import SEGMENTS

        t_design = time.perf_counter()

        def say_err(line: str) -> None:  # a line per simulated segment, with elapsed time, to stderr
            print(f"{line} ({time.perf_counter() - t_design:.0f} s)", file=sys.stderr, flush=True)

        d = design(robot, args.segments or SEGMENTS, seconds=args.seconds, seed=args.seed, progress=say_err)
        shares, plan = d.shares, d.to_json()
        if not args.json:
            print(format_design(plan), flush=True)
        if args.design_only:
            return {"robot": robot.name, "design": plan}
    kw = {"fixed_base": args.fixed_base, "robot": robot}
    ground = None
    if args.world == "real":
        frozen = freeze(prof, args.seed, robot)
        kw.update(profile=frozen, terrain="flat")
        if args.terrain == "lumpy":
            ground = rough_ground(float(frozen.frozen.terrain_amplitude), seed=args.seed)
    env = make_world(args.world, **kw)
    t0 = time.perf_counter()
    say = None if args.json else print
    paths = record_excitation(env, args.out, n_logs=args.logs, seconds=args.seconds, seed=args.seed,
                              scale=args.scale, progress=say, terrain=ground, segments=args.segments, shares=shares)
    env.close()
    wall = time.perf_counter() - t0
    if not args.json:
        print(f"wrote {len(paths)} log(s) of {args.seconds:g} s to {args.out} in {wall:.1f} s; "
              f"next: sgatwalk diagnose --real {args.out} --out REPORT_DIR")
    return {"robot": robot.name, "world": args.world, "profile": args.profile if args.world == "real" else None,
            "fixed_base": args.fixed_base, "recordings": paths, "wall_s": wall,
            **({"design": plan} if plan else {})}
