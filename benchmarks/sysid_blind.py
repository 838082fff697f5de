"""Blind benchmark of ``sgatwalk diagnose`` (protocol: README, "The blind proof").

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
* ``strangers``: the strangers' PyBullet world (``benchmarks/strangers``: effect models written apart
  from the candidate library, in physical forms of their own: a semi-closed-loop servo with gear play,
  elasto-plastic Stribeck friction, a transport delay behind a first-order lag, a DC-motor torque-speed
  envelope, inertial parameters beyond mass, a Perlin-noise ground, ...), used through its API and its
  effects table only; one effect per trial, each kind of its table for the base (fixed: the in-air
  kinds; ``--floating``: the torso's mass and centre of mass, foot friction, uneven ground, the
  command lag and a servo torque-constant error), scored by ``benchmarks/blind/strangers.py``: a kind
  is named right when the report names one of its families (``KIND_FAMILIES``) at a true target, or
  an equivalence class that contains one (with the segment that would separate it); a finding that
  is no true effect is a confident wrong Found.
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
    python benchmarks/sysid_blind.py --world strangers --seeds 2 --seed0 7000 --out runs/sysid_blind
    python benchmarks/sysid_blind.py --world strangers --floating --seeds 2 --seed0 7000 \
        --diagnose-families +latency,command_lowpass --out runs/sysid_blind

Trials already scored in ``OUT/WORLD/results.jsonl`` are skipped (resumable); ``summary.md`` is
rewritten after every trial. Prints the summary, or with ``--json`` one JSON object (settings,
``metrics`` and ``text``, progress on stderr); a result is saved by ``python -m tools.results save
NAME -- python benchmarks/sysid_blind.py ...``.
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

import numpy as np  # noqa: E402

__all__ = ["SOURCES", "ANGLE_NOISE", "CLASSES", "CLASSES_FLOATING", "FAMILIES", "GYRO_NOISE", "MIN_LINK_MASS", "NOISE",
           "NOMINAL", "SEED_ORDER", "RefereeRealWorld", "RefereeSimWorld", "draw_effect", "draw_trial",
           "explicit_damping_stable_joints", "explicit_spring_stable_joints", "main", "make_world", "opaque_id",
           "plan_trials",
           "record", "roughness_truth", "run_diagnose", "score", "summarize", "trial_id"]


# ------------------------------------------------------------------------------------------ main
def main(argv=None) -> int:
    """Run (or resume) the blind benchmark for one world; see the module docstring. Returns 0."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--world", choices=("sim", "real", "strangers"), default="sim",
                    help="sim: MuJoCo sim-as-real; real: the project's PyBullet world; strangers: the strangers' "
                         "PyBullet world (benchmarks.strangers: effect forms written apart from the candidate "
                         "library; one effect per trial, scored by benchmarks/blind/strangers.py)")
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
    ap.add_argument("--json", action="store_true",
                    help="print one JSON object (the run's settings, \"metrics\" and \"text\": the summary); "
                         "progress goes to stderr")
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
    if args.world == "strangers":
        return _run_strangers(args, root, robot)
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
        _say(args, f"calibrated engine gap on {logs_dir}")
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
        _say(args, f"{tid}: truth {[(e['family'], e['targets'], [round(v, 4) for v in e['values']]) for e in hidden]} "
                   f"-> {rep['model']} | top1 {sc['pred_top1']} | after/floor {sc['rms_after_over_floor']:.2f} | "
                   f"{sc['runtime_s']:.0f} s")
        with open(os.path.join(root, "summary.md"), "w") as f:
            f.write(summarize(rows, args.world, world_classes, args.noise))
    text = summarize(rows, args.world, world_classes, args.noise)
    with open(os.path.join(root, "summary.md"), "w") as f:
        f.write(text)
    _emit(args, text, {"world": args.world, "floating": args.floating, "excitation": args.excitation,
                       "seed0": args.seed0, "seeds": args.seeds, "two_effect": args.two_effect, "logs": args.logs,
                       "seconds": args.seconds, "encoder_noise_mrad": args.noise,
                       "calibration_noise_mrad": 1000 * NOISE, "extra_classes": extra,
                       "diagnose_families": args.diagnose_families, "metrics": metrics(rows)})
    return 0


def _say(args, line: str) -> None:
    """A progress line: to stderr with ``--json`` (stdout is then the one JSON object), else stdout."""
    print(line, file=sys.stderr if args.json else sys.stdout, flush=True)


def _emit(args, text: str, result: dict) -> None:
    """The run's result: the summary ``text``, or with ``--json`` one JSON object (``result`` and
    ``"text"``), which ``python -m tools.results save NAME -- python benchmarks/sysid_blind.py ...`` stores."""
    print(json.dumps({**result, "text": text}, default=lambda o: o.item() if hasattr(o, "item") else str(o))
          if args.json else text, flush=True)


def _run_strangers(args, root: str, robot) -> int:
    """The strangers' setting (``--world strangers``): single-effect trials of every kind of
    ``benchmarks.strangers.effects`` for the base (and "none"), ``--seeds`` per kind, calibrated on
    "none" logs of the strangers' world, scored by :func:`benchmarks.blind.strangers.score`. Resumable
    like the other worlds (``results.jsonl``)."""
    from benchmarks.blind import strangers as st

    fixed = not args.floating
    os.makedirs(root, exist_ok=True)
    res_path = os.path.join(root, "results.jsonl")
    done = {}
    if os.path.exists(res_path):
        for line in open(res_path):
            r = json.loads(line)
            done[r["trial"]] = r
    cal_dir = os.path.join(root, "calibration")
    cal_file = os.path.join(cal_dir, "calibration.json")
    if not os.path.exists(cal_file):
        logs_dir = os.path.join(root, "none_logs")
        if not os.path.isdir(logs_dir):
            record("strangers", [], logs_dir, args.calibration_logs or 2 * args.logs, args.seconds, args.seed0 - 1,
                   fixed, args.excitation)
        run_diagnose(["diagnose", "--real", logs_dir, "--out", cal_dir, "--calibrate"])
        _say(args, f"calibrated engine gap on {logs_dir}")
    kinds = st.kinds(fixed) if not args.classes else args.classes.split(",")
    rows = list(done.values())
    for s_i in range(args.seeds):
        order = np.random.default_rng(args.seed0 + s_i).permutation(len(kinds))
        for ci in order:
            kind = kinds[ci]
            tid = f"stranger_{s_i:02d}_{kind}"
            if tid in done:
                continue
            seed, hidden = st.draw_trial(s_i, kind, args.seed0, robot)
            tdir = os.path.join(root, "trials", opaque_id(tid, args.seed0))
            truth_dir = os.path.join(root, "truth")
            os.makedirs(truth_dir, exist_ok=True)
            truth_text = json.dumps({"trial": tid, "effects": hidden}, indent=1)
            with open(os.path.join(truth_dir, f"{tid}.json"), "w") as f:
                f.write(truth_text)
            logs_dir = os.path.join(tdir, "logs")
            t_rec = record("strangers", hidden, logs_dir, args.logs, args.seconds, seed % 100000, fixed,
                           args.excitation, noise=args.noise / 1000) if not os.path.isdir(logs_dir) else 0.0
            rep = run_diagnose(["diagnose", "--real", logs_dir, "--out", os.path.join(tdir, "report"),
                                "--calibration", cal_file, "--no-plots",
                                *(["--families", args.diagnose_families] if args.diagnose_families else [])])
            sc = st.score(hidden, rep, robot)
            row = {"trial": tid, "kind": "single", "seed": s_i, "truth_class": kind, "truth": hidden,
                   "truth_sha256": hashlib.sha256(truth_text.encode()).hexdigest(), "report_model": rep["model"],
                   "verdict": rep["verdict"], "score": sc, "record_s": t_rec, "n_logs": args.logs,
                   "seconds": args.seconds}
            rows.append(row)
            with open(res_path, "a") as f:
                f.write(json.dumps(row) + "\n")
            _say(args, f"{tid}: truth {[(e['family'], e['targets'], [round(v, 4) for v in e['values']]) for e in hidden]} "
                       f"-> found {sc['found']} classes {sc['equivalent']} | right {sc['named_right']} | wrong "
                       f"{sc['wrong_found']} | {sc['runtime_s']:.0f} s")
            with open(os.path.join(root, "summary.md"), "w") as f:
                f.write(st.summarize(rows, fixed, args.noise))
    text = st.summarize(rows, fixed, args.noise)
    with open(os.path.join(root, "summary.md"), "w") as f:
        f.write(text)
    _emit(args, text, {"world": "strangers", "floating": args.floating, "excitation": args.excitation,
                       "seed0": args.seed0, "seeds": args.seeds, "logs": args.logs, "seconds": args.seconds,
                       "encoder_noise_mrad": args.noise, "calibration_noise_mrad": 1000 * NOISE,
                       "diagnose_families": args.diagnose_families, "kinds": kinds, "metrics": st.metrics(rows)})
    return 0


if __name__ == "__main__":
    sys.exit(main())
