"""``sgatwalk diagnose``: locate where the sim and real recordings differ, name the missing physics,
fit it and show the held-out fit improve.

Reads recordings (Parquet files or folders of them, any that follow the schema of
``envs/recording.py``; ground truth optional), replays their commands in the MuJoCo sim from the
measured start state, and prints a report: a verdict (held-out RMS before -> after against the
noise floor), each effect found in physics words with where it is and its value with a 95 %
interval, what was considered and rejected, what this data cannot tell apart (and which
experiment would), and the residual left. Writes ``report.json``, ``report.txt``, plots and
``identified_model.xml`` (the sim with the effects, MJCF) into ``--out``. Input files are only read.
The robot is the recordings' (``meta["robot"]``: the NAO, Unitree G1 or PAL Talos); all recordings
must be of one robot.

Floating-base recordings are replayed in short windows, each started from the torso state
estimated from the IMU, the encoders and the foot force sensors (contact-aided, flat ground), as
on a real robot; ``gt.*`` ground-truth columns a simulator wrote are ignored unless
``--use-ground-truth`` is given. The report says which was used.

``--calibrate`` treats the recordings as logs of a real world with no injected effects (profile
"none") and writes ``calibration.json``: the engine gap that later diagnoses (``--calibration
FILE``) are judged against.
"""

from __future__ import annotations

import argparse
import json
import os
import sys

from common.files import atomic_write_text
import experiments.cli.argtypes as A


def register(sub) -> argparse.ArgumentParser:
    p = sub.add_parser("diagnose", help="find, name and fit the physics the sim misses (system identification)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--real", type=A.in_path, required=True, nargs="+", metavar="DIR_OR_FILE",
                   help="recordings of the real robot: Parquet files and/or folders of them")
    from robots import ROBOT_NAMES  # lazy: the parser is built for every command

    p.add_argument("--sim", default="auto", choices=("auto",) + tuple(ROBOT_NAMES),
                   help="sim model to diagnose: auto (default: the MuJoCo sim of the recordings' robot, "
                        "meta['robot']) or a robot name, which must be the recordings' robot")
    p.add_argument("--out", type=A.out_dir, required=True, metavar="REPORT_DIR", help="folder for the report")
    p.add_argument("--calibration", type=A.in_file, metavar="FILE", help="engine-gap calibration (from --calibrate on 'none' logs)")
    p.add_argument("--calibrate", action="store_true", help="the recordings have no injected effects: write "
                   "REPORT_DIR/calibration.json (engine-gap baseline) instead of a diagnosis")
    p.add_argument("--families", help="comma list of candidate families (default: actuator families for fixed-base "
                   "logs; contact families (foot_friction, ground_compliance) and the torso's mass and centre of mass for "
                   "floating-base logs, whose torso mass is weighed on the feet when they have foot forces); "
                   "torque_constant (a servo error scaling kp and kd together), parallel_spring (a passive "
                   "-k q toward the zero angle), pd_gain_all (one kp scale common to every servo), coulomb_friction_all and "
                   "viscous_damping_all (one dry / viscous friction on every joint) are screened only "
                   "when listed here; +NAME adds to the default")
    p.add_argument("--base-report", type=A.in_file, metavar="REPORT_JSON", help="keep the effects of an earlier diagnosis fixed "
                   "(bottom-up staging: diagnose fixed-base logs first, then stepping logs with their report)")
    p.add_argument("--passes", type=A.count(1, 100), default=3, help="screen/refit passes (default 3)")
    p.add_argument("--time-budget", type=A.real(0.0, 86400.0, unit='s'), default=300.0, metavar="SECONDS",
                   help="start no new search step after this long (default 300; 0 = no limit)")
    p.add_argument("--use-ground-truth", action="store_true",
                   help="replay floating-base recordings from their gt.* ground-truth base state (a simulator's; "
                        "default: ignore it and estimate the state from IMU, encoders and foot forces, as on a robot)")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    return p


def run(args) -> dict:
    from sysid.diagnose import calibrate, diagnose  # lazy: loads the engines; keeps sgatwalk --help fast
    from sysid.report import format_report, public_json, write_report  # lazy: loads the engines; keeps sgatwalk --help fast

    with A.user_input():
        logs, robot, cal, fams, base = _inputs(args)
    say = None if args.json else (lambda s: print(s, file=sys.stderr))
    os.makedirs(args.out, exist_ok=True)
    if args.calibrate:
        cal = calibrate(logs, robot=robot, use_ground_truth=args.use_ground_truth)
        p = os.path.join(args.out, "calibration.json")
        atomic_write_text(p, json.dumps(public_json(cal), indent=1))
        if not args.json:
            worst = sorted(cal["gap_rms"].items(), key=lambda kv: -kv[1])[:3]
            print(f"engine gap from {cal['n_logs']} log(s): sensor σ {1000 * cal['sigma']['encoders']:.3f} mrad; "
                  f"largest gap {', '.join(f'{k} {1000 * v:.3f} mrad' for k, v in worst)}; "
                  "baseline model (engine gap in candidate terms): "
                  f"{', '.join(f'{k} = {v:.4g}' for k, v in cal['baseline_model'].items()) or 'none'}; "
                  f"base state {cal['base_state']}; wrote {p}")
        return {"calibration": p, **public_json(cal)}
    rep = diagnose(logs, calibration=cal, families=fams, max_rounds=args.passes, progress=say, base_model=base,
                   time_budget_s=args.time_budget or None, robot=robot, use_ground_truth=args.use_ground_truth)
    paths = write_report(rep, logs, args.out, plots=not args.no_plots)
    if not args.json:
        print(format_report(rep))
        print(f"wrote {', '.join(v if isinstance(v, str) else ', '.join(v) for v in paths.values())}")
    out = public_json(rep)
    out["files"] = paths
    return out


def _inputs(args):
    """What the user gave, read and checked: (logs, robot, calibration or None, families or None, base
    model or None).

    Raises:
        ValueError, FileNotFoundError: unreadable logs, a calibration or report of other logs (named).
    """
    from sysid.data import load_logs  # lazy: loads the engines

    logs = load_logs(args.real, use_ground_truth=args.use_ground_truth)
    robot = logs[0].robot
    if args.sim != "auto":
        from robots import get_robot  # lazy: g1/talos parse their URDFs

        if get_robot(args.sim).name != robot.name:
            raise ValueError(f"--sim {args.sim}: the recordings are of robot {robot.name!r}")
    cal = None
    if args.calibration and not args.calibrate:
        with open(args.calibration) as f:
            try:
                cal = json.load(f)
            except json.JSONDecodeError as exc:
                raise ValueError(f"{args.calibration}: not a JSON calibration ({exc})") from None
        if not isinstance(cal, dict) or cal.get("kind") != "sgatwalk-sysid-calibration":
            raise ValueError(f"{args.calibration}: not a calibration written by 'sgatwalk diagnose --calibrate'")
        if bool(cal.get("fixed_base")) != logs[0].fixed_base:
            raise ValueError(f"{args.calibration}: calibrated on {'fixed' if cal.get('fixed_base') else 'floating'}-base "
                             "logs; the recordings are not")
        missing = [n for n in robot.joint_names if n not in cal.get("gap_rms", {})]
        if missing:
            raise ValueError(f"{args.calibration}: calibrated on another robot's logs (no engine gap for joint "
                             f"{missing[0]} of {robot.name})")
    fams = _families(args.families, logs) if args.families else None
    base = None
    if args.base_report:
        from sysid.report import terms_from_labels  # lazy: loads the engines

        with open(args.base_report) as f:
            try:
                prev = json.load(f)
                base = terms_from_labels({**prev.get("base_model", {}), **prev["model"]})
            except (json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
                raise ValueError(f"{args.base_report}: not a report.json of sgatwalk diagnose ({exc})") from None
        alien = [t.label() for t in base if t.target is not None and t.target not in robot.joint_names
                 and t.target not in robot.links]
        if alien:
            raise ValueError(f"{args.base_report}: effect {alien[0]} is not on a joint or link of {robot.name} "
                             "(a report of another robot)")
    return logs, robot, cal, fams, base


def _families(text: str, logs) -> list[str]:
    """``--families``: a comma list of family names, or ``+NAME,...`` for the default families of the
    logs (actuator families for a fixed base; contact families and the torso's mass and CoM for a
    floating one: ``sysid.candidates.FLOATING_BASE_FAMILIES``) and those, in library order.

    Raises:
        ValueError: an unknown family name (a usage error).
    """
    from sysid.candidates import FAMILIES, FIXED_BASE_FAMILIES, FLOATING_BASE_FAMILIES  # lazy: loads mujoco

    names = [f.strip() for f in text.lstrip("+").split(",") if f.strip()]
    bad = [f for f in names if f not in FAMILIES]
    if bad:
        raise ValueError(f"--families: unknown famil{'ies' if len(bad) > 1 else 'y'} {', '.join(bad)}; "
                         f"known: {', '.join(FAMILIES)}")
    if not text.startswith("+"):
        return names
    default = FIXED_BASE_FAMILIES if logs[0].fixed_base else FLOATING_BASE_FAMILIES
    return [f for f in FAMILIES if f in default or f in names]
