"""Blind benchmark of ``sgatwalk diagnose`` (issue 8; protocol: README, "The blind proof").

A referee draws hidden effects (one family or "none", or two families), injects them in a world,
records excitation logs with 1 mrad encoder noise, writes **only the recordings** to a folder the
tool reads (metadata stripped of the profile and effect values), keeps the truth in a separate
folder the tool never sees (its SHA-256 goes into the results), runs ``sgatwalk diagnose`` on the
folder (after an engine-gap calibration on "none" logs of the same world) and scores the report.

Worlds (the referee's injection is its own code, independent of the candidate models in ``sysid/``):

* ``sim`` (sim-as-real): MuJoCo with the PD law computed in Python and applied as motor torque at
  each 1 ms step; latency as a command FIFO with ±1 ms jitter per control step (the candidate is
  MuJoCo's interpolated ``actuator_delay``), backlash as a dead band on the PD error (the
  candidate is a series play hinge), viscous damping inside the clipped PD torque (the candidate
  is ``dof_damping``), kp and torque limit in the Python PD, Coulomb friction as MuJoCo
  ``frictionloss`` with hard stiction (2 ms constraint time constant), link mass / armature as model edits, sensor bias as an offset on the logged
  angle, joint compliance as a massless motor behind a spring (:class:`_SeriesSpring`, backward
  Euler; the candidate is a MuJoCo series hinge with joint stiffness and a light motor body).
* ``real``: the PyBullet world of ``envs/bullet_world.py`` (its own effect code: explicit PD,
  velocity-motor Coulomb friction, dead-band backlash, mass scaling), plus a referee FIFO with
  jitter for latency, a logged-angle offset for sensor bias and the same massless-motor spring
  for joint compliance. PyBullet has no armature, so the
  ``armature`` class is run in the sim world only.

Metrics: family top-1 with a confusion matrix (top-1 = the effect whose removal hurts the
held-out fit most; "none" = no effect reported), false positives on "none", joint/link
localisation precision/recall (family and target must match), median parameter error
|θ̂-θ|/|θ-θ_nominal| (latency: absolute ms), held-out RMS after / noise floor and gap closed,
95 % CI coverage, runtime; two-effect trials: both families found, exact family set, precision.

Usage::

    python benchmarks/sysid_blind.py --world sim --seeds 5 --two-effect 20 --out runs/sysid_blind
    python benchmarks/sysid_blind.py --world real --seeds 5 --two-effect 20 --out runs/sysid_blind

Trials already scored in ``OUT/WORLD/results.jsonl`` are skipped (resumable); ``summary.md`` is
rewritten after every trial.
"""

from __future__ import annotations

# Thin CLI entry point: the referee (hidden effects, trials, worlds, recording), the scorer and the
# markdown report live in the ``benchmarks/blind`` package; the names below are re-exported so that
# ``benchmarks.sysid_blind.<name>`` keeps working.

import argparse
import hashlib
import json
import os
import shutil
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from benchmarks.blind.families import (ANGLE_NOISE, CLASSES, CLASSES_FLOATING, FAMILIES,  # noqa: E402
                                       GYRO_NOISE, MIN_LINK_MASS, NOISE, NOMINAL, SEED_ORDER)
from benchmarks.blind.referee import (SOURCES, draw_effect, draw_trial, explicit_damping_stable_joints,  # noqa: E402
                                      explicit_spring_stable_joints, opaque_id, plan_trials, record,
                                      roughness_truth, run_diagnose, trial_id)
from benchmarks.blind.report import metrics, summarize  # noqa: E402
from benchmarks.blind.scorer import detectable, score  # noqa: E402
from benchmarks.blind.worlds import RefereeRealWorld, RefereeSimWorld, make_world  # noqa: E402
from robots import nao_h25  # noqa: E402

__all__ = ["SOURCES", "ANGLE_NOISE", "CLASSES", "CLASSES_FLOATING", "FAMILIES", "GYRO_NOISE", "MIN_LINK_MASS", "NOISE",
           "NOMINAL", "SEED_ORDER", "RefereeRealWorld", "RefereeSimWorld", "draw_effect", "draw_trial",
           "explicit_damping_stable_joints", "explicit_spring_stable_joints", "main", "make_world", "opaque_id",
           "plan_trials",
           "record", "roughness_truth", "run_diagnose", "score", "summarize", "trial_id"]


# ------------------------------------------------------------------------------------------ main
def main(argv=None) -> int:
    """Run (or resume) the blind benchmark for one world; see the module docstring. Returns 0."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--world", choices=("sim", "real"), default="sim")
    ap.add_argument("--seeds", type=int, default=5, help="seeds per class (single-effect trials)")
    ap.add_argument("--two-effect", type=int, default=20, help="number of two-effect trials")
    ap.add_argument("--logs", type=int, default=3, help="logs per trial (one held out)")
    ap.add_argument("--seconds", type=float, default=6.0, help="seconds per log")
    ap.add_argument("--calibration-logs", type=int, help="'none' logs for the engine-gap calibration "
                    "(default: twice --logs, so its own diagnosis has held-out logs to keep a gap term on)")
    ap.add_argument("--out", default="runs/sysid_blind")
    ap.add_argument("--seed0", type=int, default=1000)
    ap.add_argument("--classes", help="comma list to restrict the single-effect classes")
    ap.add_argument("--floating", action="store_true", help="standing/stepping logs, contact families "
                    "(foot friction, ground compliance) instead of the fixed-base actuator families")
    ap.add_argument("--save", metavar="NAME", help="also write docs/results/NAME.json (headline figures, for the README)")
    ap.add_argument("--excitation", choices=SOURCES, default="protocol",
                    help="the logs' excitation: the project's protocol (sgatwalk excite) or the referee's own "
                         "random multisine + steps (fixed base only; benchmarks/blind/excitation.py)")
    ap.add_argument("--noise", type=float, default=1000 * NOISE, metavar="MRAD",
                    help="encoder noise of the trial logs [mrad] (default 1; the engine-gap calibration logs keep "
                         "1 mrad, so 3 tests a floor taken from noisier logs than the calibration's)")
    ap.add_argument("--extra-classes", default="", metavar="LIST",
                    help="comma list of classes outside the default set to draw as well (e.g. torque_constant)")
    ap.add_argument("--diagnose-families", metavar="LIST",
                    help="passed to sgatwalk diagnose --families (e.g. +torque_constant: the defaults and that one)")
    args = ap.parse_args(argv)
    if not args.noise > 0:
        ap.error(f"--noise must be positive, got {args.noise}")
    load_before = os.getloadavg()[0]
    robot = nao_h25()
    if args.floating and args.excitation != "protocol":
        ap.error("--excitation referee is for a fixed base only")
    extra = [c.strip() for c in args.extra_classes.split(",") if c.strip()]
    if any(c not in SEED_ORDER for c in extra):
        ap.error(f"--extra-classes: unknown class(es) {', '.join(c for c in extra if c not in SEED_ORDER)}; "
                 f"known: {', '.join(dict.fromkeys(SEED_ORDER))}")
    root = os.path.join(args.out, args.world + ("_floating" if args.floating else "")
                        + ("" if args.excitation == "protocol" else f"_{args.excitation}")
                        + ("" if args.noise == 1000 * NOISE else f"_noise{args.noise:g}")
                        + "".join(f"_{c}" for c in extra)
                        + (f"_fam{args.diagnose_families.replace(',', '_').replace('+', '')}"
                           if args.diagnose_families else ""))
    fixed = not args.floating
    world_classes = (CLASSES_FLOATING if args.floating else CLASSES)[args.world] + extra
    os.makedirs(root, exist_ok=True)
    res_path = os.path.join(root, "results.jsonl")
    done = {}
    if os.path.exists(res_path):
        for line in open(res_path):
            r = json.loads(line)
            if "detectable" not in r["score"]:  # scored before the flag existed: from the trial's report
                with open(os.path.join(root, "trials", opaque_id(r["trial"], args.seed0), "report", "report.json")) as f:
                    r["score"]["detectable"] = detectable(json.load(f))
            done[r["trial"]] = r
    # engine-gap calibration on "none" logs of this world (the tool's --calibrate)
    cal_dir = os.path.join(root, "calibration")
    cal_file = os.path.join(cal_dir, "calibration.json")
    if not os.path.exists(cal_file):
        logs_dir = os.path.join(root, "none_logs")
        if not os.path.isdir(logs_dir):
            record(args.world, [], logs_dir, args.calibration_logs or 2 * args.logs, args.seconds, args.seed0 - 1,
                   fixed, args.excitation)
        run_diagnose(["diagnose", "--real", logs_dir, "--out", cal_dir, "--calibrate"])
        print(f"calibrated engine gap on {logs_dir}", flush=True)
    classes = world_classes if not args.classes else args.classes.split(",")
    pair_fams = [c for c in world_classes if c != "none"]
    trials = plan_trials(classes, args.seeds, args.two_effect, args.seed0)
    rows = list(done.values())
    for kind, s, cls in trials:
        tid = trial_id(kind, s, cls)
        if tid in done:
            continue
        seed, hidden = draw_trial(kind, s, cls, args.seed0, pair_fams, robot, args.logs)
        tdir = os.path.join(root, "trials", opaque_id(tid, args.seed0))
        truth_dir = os.path.join(root, "truth")
        os.makedirs(truth_dir, exist_ok=True)
        truth_text = json.dumps({"trial": tid, "effects": hidden}, indent=1)
        truth_file = os.path.join(truth_dir, f"{tid}.json")
        logs_dir = os.path.join(tdir, "logs")
        if os.path.isdir(logs_dir) and (not os.path.exists(truth_file) or open(truth_file).read() != truth_text):
            shutil.rmtree(logs_dir)  # recorded for other hidden effects (e.g. a class list that changed)
        with open(truth_file, "w") as f:
            f.write(truth_text)
        t_rec = record(args.world, hidden, logs_dir, args.logs, args.seconds, seed % 100000, fixed, args.excitation,
                       noise=args.noise / 1000) \
            if not os.path.isdir(logs_dir) else 0.0
        rep = run_diagnose(["diagnose", "--real", logs_dir, "--out", os.path.join(tdir, "report"),
                            "--calibration", cal_file, "--no-plots",
                            *(["--families", args.diagnose_families] if args.diagnose_families else [])])
        sc = score(hidden, rep)
        row = {"trial": tid, "kind": kind, "seed": s, "truth_class": cls if kind == "single" else None,
               "truth": hidden, "truth_sha256": hashlib.sha256(truth_text.encode()).hexdigest(),
               "report_model": rep["model"], "verdict": rep["verdict"], "score": sc, "record_s": t_rec,
               "n_logs": args.logs, "seconds": args.seconds}
        rows.append(row)
        with open(res_path, "a") as f:
            f.write(json.dumps(row) + "\n")
        print(f"{tid}: truth {[(e['family'], e['targets'], [round(v, 4) for v in e['values']]) for e in hidden]} -> "
              f"{rep['model']} | top1 {sc['pred_top1']} | after/floor {sc['rms_after_over_floor']:.2f} | "
              f"{sc['runtime_s']:.0f} s", flush=True)
        with open(os.path.join(root, "summary.md"), "w") as f:
            f.write(summarize(rows, args.world, world_classes, args.noise))
    with open(os.path.join(root, "summary.md"), "w") as f:
        f.write(summarize(rows, args.world, world_classes, args.noise))
    print(summarize(rows, args.world, world_classes, args.noise))
    if args.save:
        from tools.readme import save_benchmark

        res = {"world": args.world, "floating": args.floating, "excitation": args.excitation, "seed0": args.seed0,
               "seeds": args.seeds, "two_effect": args.two_effect, "logs": args.logs, "seconds": args.seconds,
               "encoder_noise_mrad": args.noise, "calibration_noise_mrad": 1000 * NOISE, "extra_classes": extra,
               "diagnose_families": args.diagnose_families, "metrics": metrics(rows)}
        print(save_benchmark(args.save, "benchmarks/sysid_blind.py", argv if argv is not None else sys.argv[1:], res,
                             load_before))
    return 0


if __name__ == "__main__":
    sys.exit(main())
