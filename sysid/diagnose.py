"""The diagnosis pipeline: calibrate → localise → screen → refit → prune on held-out → intervals.

:func:`diagnose` takes loaded logs and returns the report as a JSON-able dict (the keys of
``REPORT_DIR/report.json``); :func:`calibrate` turns recordings of a real world without injected
effects (profile "none") into the engine-gap baseline that later diagnoses are judged against.
Selection rules (this project's; BIC after Schwarz, Ann. Statist. 6(2), 1978), with cost C = Σ_channels
mean((e/floor)²) on held-out
windows (C = number of channels when every channel sits at its floor):

* nothing to explain: no joint's residual energy exceeds 1.5 floor² (RMS 1.22 floors) on training or
  held-out logs;
* a screening round is kept if it lowers the held-out cost by at least
  max(0.25, 5 % of the excess C - k) and lowers the training BIC by more than 10;
* a term, then a whole family, is dropped if removing it (families: and refitting the rest)
  raises the held-out cost by less than that same margin (backward elimination);
* a selected term is reported as Found only if it survives held-out elimination, its 95 % interval
  excludes the sim's value, it is not at a bound of its family and it does not only compensate
  another term; the others are reported as uncertain / compensating, with the reason (:func:`_vet`);
* and only if its family beats the best fit of every other family of its equivalence classes
  (:mod:`sysid.equivalence`) in its place on the held-out logs, beyond the noise and by the margin
  (:func:`_equivalence`); otherwise the report names the class, its candidates and the excitation
  segment that would tell them apart (``report["equivalent"]``), and the identified model keeps the
  best-fitting candidate.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import nnls

from sysid.candidates import (FAMILIES, FIXED_BASE_FAMILIES, FLOATING_BASE_FAMILIES, PLAY_FAMILIES, SHAPE_FAMILIES, Term,
                              joints_above, term_allowed, term_bounds, term_link, term_min_effect, term_probe)
from sysid.data import (BASE_ESTIMATED, Log, base_state_source, split_by_trajectory,
                         without_ground_truth)
from sysid.identify import (FLAG_ENERGY, Problem, ScreenResult, confidence, flagged_joints, refit, screen,
                            two_sided)
from sysid.model import STRIBECK_VELOCITY
from sysid.replay import IMU_CHANNELS, MUJOCO_WARNINGS, Window, predict, whole_logs, windows
from sysid.roughness import CORRELATION_RADIUS, RoughnessFit
from sysid.stats import integrated_autocorr, localisation, noise_sigma
from sysid.weighing import Weighing, weigh

#: Minimum noise floor [rad] (noise-free logs would otherwise divide by ~0).
MIN_FLOOR = 1e-5
#: Encoder noise [rad] below which recordings are taken as noise-free (simulated): NAO-like encoders
#: are ~1 mrad, so a diagnosis without a calibration warns that any engine gap will read as physics.
NOISE_FREE_SIGMA = 1e-4
#: Window length of windowed replay for floating-base logs [s] (multiple shooting, Ribeiro et al.,
#: Automatica 2020; 0.5 s is this project's choice).
WINDOW_S = 0.5

EXPERIMENTS = {
    frozenset({"pd_gain", "joint_compliance"}): "a chirp through 1-4 Hz and steps: a series spring takes the servo "
                                                "damping off the output (a larger, slower-settling resonance), a kp "
                                                "error keeps it; or motor current against output deflection",
    frozenset({"pd_gain", "torque_constant"}): "target steps of two sizes and a chirp through the servo resonance: a "
                                               "torque-constant error scales the damping with the stiffness (same "
                                               "overshoot, slower or faster), a kp-only error changes the overshoot",
    frozenset({"torque_constant", "joint_compliance"}): "a chirp through 1-4 Hz and steps: a series spring takes the "
                                                        "servo damping off the output, a torque-constant error keeps "
                                                        "its ratio to the stiffness",
    frozenset({"pd_gain", "parallel_spring"}): "hold steps to targets of both signs and two sizes with the joint "
                                               "unloaded (gravity across the joint axis or the link supported): a "
                                               "kp error still reaches every target, a parallel spring falls short "
                                               "by k / (kp + k) of the target, in proportion to it and toward 0",
    frozenset({"sensor_bias", "parallel_spring"}): "holds at several angles of both signs: an encoder offset is the "
                                                   "same at every angle, a parallel spring's shortfall grows with "
                                                   "the angle and changes sign with it",
    frozenset({"joint_compliance", "parallel_spring"}): "holds at several unloaded targets and a chirp through 1-4 "
                                                        "Hz: a series spring reaches unloaded targets and takes the "
                                                        "servo damping off the output, a parallel spring falls "
                                                        "short toward 0 and stiffens the joint",
    frozenset({"backlash", "sensor_bias"}): "holds in postures with opposite gravity load on the joint, or load "
                                            "reversals: an encoder offset stays, backlash under a one-sided load "
                                            "flips sign with the load",
    frozenset({"pd_gain", "link_mass"}): "posture holds in several postures plus a chirp: a mass error follows the "
                                         "posture-dependent gravity torque, a kp error also shifts the servo resonance",
    frozenset({"latency", "pd_gain"}): "a chirp to 4 Hz: latency gives phase lag growing with frequency at constant "
                                       "gain, a kp change alters gain and resonance",
    frozenset({"latency", "viscous_damping"}): "a chirp to 4 Hz: latency lags phase at constant gain, damping "
                                               "lowers gain with frequency",
    frozenset({"coulomb_friction", "backlash"}): "slow ramps at two speeds and load reversals: backlash gives a "
                                                 "speed-independent hysteresis without energy loss",
    frozenset({"coulomb_friction", "viscous_damping"}): "ramps at two different speeds: Coulomb torque does not "
                                                        "grow with speed",
    frozenset({"viscous_damping", "armature"}): "a chirp to 4 Hz: damping scales with frequency, armature with its "
                                                "square (resonance shift)",
    frozenset({"pd_gain", "armature"}): "a chirp through the servo resonance: armature lowers the resonance without "
                                        "changing the static stiffness under gravity holds",
    frozenset({"sensor_bias", "link_mass"}): "holds in postures with opposite gravity load on the joint",
    frozenset({"sensor_bias", "pd_gain"}): "holds in postures with opposite gravity load on the joint",
}


def _experiment(a: str, b: str) -> str:
    return EXPERIMENTS.get(frozenset({a, b}), "a longer chirp (0.3-4 Hz) and posture holds on the joints involved")


def _channel_names(robot, with_imu: bool) -> list[str]:
    """The robot's n joint names, then :data:`sysid.replay.IMU_CHANNELS` with an IMU."""
    n = list(robot.joint_names)
    if with_imu:
        n += list(IMU_CHANNELS)
    return n


def _floor(logs: list[Log], wins: list[Window], nominal: list[np.ndarray], with_imu: bool,
           calibration: dict | None, robot) -> tuple[np.ndarray, dict]:
    """Noise floor per channel, (k,) [rad, rad/s]: sqrt(σ² + gap²), never below MIN_FLOOR.

    σ is always the diagnosed logs' own sensor noise (:func:`sysid.stats.noise_sigma` of the
    nominal residual: encoders, and with an IMU torso angles and gyro); the engine gap is the
    calibration's ``gap_rms`` per channel (0 without a calibration). The calibration's own σ is not
    used: logs noisier (or cleaner) than the calibration's are judged against their own noise.

    Returns:
        (floor, {"sigma": {"encoders": [rad], "angle": [rad], "gyro": [rad/s]} (the latter two with
        an IMU), "gap": (k,) engine gap [rad, rad/s]}).
    """
    from sysid.replay import measured

    res = [measured(logs[w.log], w, with_imu) - p[0] for w, p in zip(wins, nominal)]
    cmds = [logs[w.log].cmd[w.k0:w.k1] for w in wins]
    nj = len(robot.joint_names)
    sig = noise_sigma([r[:, :nj] for r in res], cmds)
    sigma = {"encoders": float(max(np.median(sig), MIN_FLOOR))}
    k = nj + (len(IMU_CHANNELS) if with_imu else 0)
    floor = np.full(k, sigma["encoders"])
    if with_imu:
        s_imu = noise_sigma([r[:, nj:] for r in res])
        sigma["angle"] = float(max(np.median(s_imu[:2]), MIN_FLOOR))
        sigma["gyro"] = float(max(np.median(s_imu[2:]), 1e-4))
        floor[nj:nj + 2] = sigma["angle"]
        floor[nj + 2:nj + 5] = sigma["gyro"]
    gap = np.zeros(k)
    if calibration:
        g = calibration.get("gap_rms", {})
        for i, nm in enumerate(_channel_names(robot, with_imu)):
            gap[i] = float(g.get(nm, 0.0))
    floor = np.sqrt(floor ** 2 + gap ** 2)
    return np.maximum(floor, MIN_FLOOR), {"sigma": sigma, "gap": gap}


def _margin(cost: float, k: int) -> float:
    return max(0.25, 0.05 * max(cost - k, 0.0))


def _bic(problem: Problem, values: dict, n_params: int) -> float:
    R = problem.residuals(problem.predict([values], "train"), "train")[0]
    n = len(R)
    n_eff = max(10.0, 0.1 * n)
    return n_eff * math.log(max(float(R @ R) * n_eff / n, 1e-300) / n_eff) + n_params * math.log(n_eff)


def _below_min_effect(values: dict, robot=None) -> list[Term]:
    """Terms whose value is within their family's ``min_effect`` (scaled to ``robot``:
    :func:`sysid.candidates.term_min_effect`) of nominal."""
    return [t for t, v in values.items() if abs(float(v) - t.fam.nominal) < term_min_effect(t, robot)]


def _small_entry(t: Term, v: float, robot=None) -> dict:
    return {"term": t.label(), "family": t.family, "value": float(v),
            "reason": f"{t.fam.fmt(v)} is within the smallest reported effect ({term_min_effect(t, robot):g} "
                      f"{t.fam.unit}) of the sim's value"}


def _entry(t: Term, v: float, ci, robot) -> dict:
    fam = t.fam
    if fam.scope == "global":
        joints = list(robot.joint_names) if not fam.contact else []
        links = []
    elif fam.scope == "joint":
        joints, links = [t.target], []
    else:
        joints, links = [], [term_link(t)]
    link = term_link(t)
    axis = f", {t.target.split(':')[1]} axis" if t.family == "link_com" else ""
    where = ("all joints" if fam.scope == "global" and not fam.contact else "feet/ground" if fam.contact
             else f"link {link}{axis} (the root: carried by the stance legs, shows on their joints and the IMU)"
             if fam.scope == "link" and link == robot.root
             else f"link {link}{axis} (shows on {', '.join(joints_above(robot, link)[:3])})" if fam.scope == "link"
             else t.target)
    return {"family": t.family, "term_label": t.label(), "joints": joints, "links": links, "value": float(v),
            "unit": fam.unit,
            "ci95": [float(ci[0]), float(ci[1])] if ci is not None else [None, None], "nominal": fam.nominal,
            "words": fam.words, "where": where, "display": fam.fmt(v)}


#: A joint family whose stage-A column explains at least this share of what the picked family's explains
#: is fitted in its place (:func:`_compete`).
COMPETE_SHARE = 0.7


def _compete(problem: Problem, model: dict, cand: dict, sr, families, k: int, robot) -> tuple[dict, list]:
    """Fit competing joint families on the same joints and keep the best on held-out data.

    For each joint-scope family picked this round, the other joint families whose stage-A column
    explained at least :data:`COMPETE_SHARE` as much of the residual (at most 2) are fitted in its place on the
    same joints (grid starts + least squares); the held-out costs decide (the
    selection rules of this module: single-family fits ranked on held-out data). Members of the
    family's equivalence classes are left to the class test at the end (:func:`_equivalence`), and
    a joint block (kp and kd of one servo) competes once, as a whole.

    A rival that fits the held-out data within the margin of the kept family (neither better nor
    clearly worse) is a near-equivalent explanation: it goes into the returned ties, which the report
    lists under "cannot be told apart with this data" with the experiment that separates them.

    Returns:
        (the winning parameter set, [rejection records for the losers], [ties: (kept term label,
        rival term label, |cost difference|)]).
    """
    from sysid.equivalence import rival_families as class_rivals
    from sysid.identify import JOINT_BLOCKS

    new = {t: v for t, v in cand.items() if t not in model}
    fams = sorted({t.family for t in new if t.fam.scope == "joint"})
    # a joint block (kp and kd of one servo) competes once, as its first family; its members are no rivals
    block_of = {f: blk for blk in JOINT_BLOCKS for f in blk}
    fams = [f for f in fams if f not in block_of or f == block_of[f][0] or block_of[f][0] not in fams]
    # the strongest new family competes (the one screening explained most with), the others wait for
    # the class test at the end
    fams = sorted(fams, key=lambda f: -sr.family_score.get(f, 0.0))[:1]
    ties = []
    if not fams:
        return cand, [], ties
    best_c = float(problem.cost([cand], "heldout")[0])
    records = []
    for f in fams:
        targets = [t.target for t in new if t.family == f]
        top = sr.family_score.get(f, 0.0)
        rivals = [g for g, sc in sorted(sr.family_score.items(), key=lambda kv: -kv[1])
                  if g != f and g in families and FAMILIES[g].scope == "joint" and sc >= COMPETE_SHARE * top
                  and g not in block_of.get(f, ()) and g not in class_rivals(f)][:2]
        for g in rivals:
            if not all(term_allowed(Term(g, tg), robot) for tg in targets):
                continue
            alt = {t: v for t, v in cand.items() if t.family != f or t.target not in targets}
            if g in PLAY_FAMILIES and any(t.family in PLAY_FAMILIES and t.target in targets for t in alt):
                continue  # one play hinge per joint
            for tg in targets:
                alt[Term(g, tg)] = term_probe(Term(g, tg), robot)
            fit = refit(problem, alt, free=[Term(g, tg) for tg in targets], max_nfev=6)
            c_alt = float(problem.cost([fit.values], "heldout")[0])
            if c_alt < best_c - _margin(best_c, k):
                records.append({"term": ",".join(Term(f, tg).label() for tg in targets), "family": f,
                                "value": float(np.mean([cand[Term(f, tg)] for tg in targets])),
                                "reason": f"{g} on the same joints fits held-out data better "
                                          f"(cost {c_alt:.1f} vs {best_c:.1f})"})
                cand, best_c = dict(fit.values), c_alt
                break
            near = c_alt - best_c < _margin(best_c, k)
            records.append({"term": ",".join(Term(g, tg).label() for tg in targets), "family": g,
                            "value": float(np.mean([fit.values[Term(g, tg)] for tg in targets])),
                            "reason": f"fitted instead of {f} on the same joints: held-out cost {c_alt:.1f} "
                                      f"vs {best_c:.1f} ({f} kept" + ("; within the margin: near-equivalent)"
                                                                      if near else ")")})
            if near:
                ties.extend((Term(f, tg).label(), Term(g, tg).label(), abs(c_alt - best_c)) for tg in targets)
    return cand, records, ties


def _trajectory_spread(problem: Problem, model: dict) -> dict:
    """Term -> standard deviation of the estimates refitted on each log alone (train and held-out
    logs), started at the joint fit (a jackknife-like check of trajectory dependence)."""
    ests = {t: [] for t in model}
    for i in sorted({w.log for w in problem.train + problem.heldout}):
        wins = [w for w in problem.train + problem.heldout if w.log == i]
        p1 = Problem(problem.logs, wins, wins[:1], problem.floor, problem.with_imu, problem.base)
        fit = refit(p1, model, grid=False, max_nfev=4)
        problem.n_rollouts += p1.n_rollouts
        for t in model:
            ests[t].append(fit.values[t])
    return {t: float(np.std(v, ddof=1)) if len(v) > 1 else 0.0 for t, v in ests.items()}


def _robot_of(logs: list[Log], robot=None):
    """The logs' robot (``Log.robot``, from the recordings' ``meta["robot"]``), or ``robot`` if it is that one.

    Raises:
        ValueError: no logs; ``robot`` is another robot than the logs'.
    """
    if not logs:
        raise ValueError("no logs to diagnose")
    own = logs[0].robot
    if robot is not None and robot.name != own.name:
        raise ValueError(f"the logs are of robot {own.name!r}, not {robot.name!r}")
    return robot or own


def _replay_logs(logs: list[Log], use_ground_truth: bool) -> tuple[list[Log], str]:
    """The logs as a diagnosis replays them and where their base state comes from
    (:func:`sysid.data.base_state_source`): without their ``gt.*`` ground truth unless
    ``use_ground_truth`` (a real robot does not know its torso's true state).

    Raises:
        ValueError: ``use_ground_truth`` with floating-base logs that lack (some or all) ``gt.*`` columns.
    """
    if not use_ground_truth:
        logs = without_ground_truth(logs)
    source = base_state_source(logs)
    if use_ground_truth and source == BASE_ESTIMATED:
        raise ValueError("--use-ground-truth: the recordings have no gt.base, gt.quat, gt.vel and gt.angvel columns "
                         "(a real robot's recordings do not); diagnose without it")
    return logs, source


def calibrate(logs: list[Log], robot=None, baseline: bool = True, *, use_ground_truth: bool = False) -> dict:
    """Engine-gap baseline from logs of a real world with no injected effects.

    Two parts: (1) the engine gap expressed in candidate terms: a diagnosis of these logs (with
    ``baseline``); the terms it declares (e.g. a stiffer ground in PyBullet than in MuJoCo) become
    the *baseline model* every later diagnosis replays under, so injected effects are judged
    relative to it (the null-gap calibration of ``benchmarks/sysid_blind.py``); (2) the residual left by
    the baseline model per channel, with
    the sensor noise removed: the gap that widens every later noise floor.

    Returns:
        dict with ``sigma`` (noise levels of these logs: ``encoders`` [rad], with an IMU ``angle``
        [rad] and ``gyro`` [rad/s]; for reference only, a later diagnosis uses its own logs'),
        ``gap_rms`` (channel -> residual RMS of the baseline model without noise [rad]), ``rms``
        (channel -> raw residual RMS), ``baseline_model`` (term label -> value), ``n_logs``,
        ``fixed_base``, ``base_state`` (where the replays took the base state from:
        :data:`sysid.data.BASE_FIXED`, ``BASE_ESTIMATED`` or ``BASE_GROUND_TRUTH``); ``weight``
        (floating-base logs with foot forces: ``per_log_kg``, what each log weighs, the reference of a
        later diagnosis's weighing, :mod:`sysid.weighing`; else None); and ``screen``
        (the terms a plain screening picks on these logs, for the record).

    Args:
        logs: recordings of one robot (``Log.robot``, n joints).  robot: that robot (default the logs').
        use_ground_truth: replay floating-base logs from their ``gt.*`` ground-truth base state
            (default: estimated from IMU, encoders and foot forces, as a later diagnosis does by default).

    Raises:
        ValueError: ``robot`` is not the logs' robot; ``use_ground_truth`` with floating-base logs
            without ``gt.*`` columns.
    """
    robot = _robot_of(logs, robot)
    logs, source = _replay_logs(logs, use_ground_truth)
    with_imu = not logs[0].fixed_base and all("angle" in lg.imu and "gyro" in lg.imu for lg in logs)
    base_model = {}
    if baseline and len(logs) > 1:
        base_model = diagnose(logs, robot=robot, use_ground_truth=use_ground_truth)["_model_terms"]
    wins = whole_logs(logs) if logs[0].fixed_base else windows(logs, range(len(logs)), WINDOW_S)
    nominal = predict(logs, wins, [base_model], with_imu=with_imu)
    floor, info = _floor(logs, wins, nominal, with_imu, None, robot)
    from sysid.replay import measured

    names = _channel_names(robot, with_imu)
    sq = np.zeros(len(names))
    n = 0
    for w, p in zip(wins, nominal):
        e = measured(logs[w.log], w, with_imu)[1:] - p[0, 1:]
        sq += (e ** 2).sum(axis=0)
        n += len(e)
    rms = np.sqrt(sq / n)
    sig = np.array([info["sigma"]["encoders"]] * len(robot.joint_names)
                   + ([info["sigma"].get("angle", 0)] * 2 + [info["sigma"].get("gyro", 0)] * 3 if with_imu else []))
    gap = np.sqrt(np.maximum(rms ** 2 - sig ** 2, 0.0))
    problem = Problem(logs, wins, wins, floor, with_imu)
    fams = FIXED_BASE_FAMILIES if logs[0].fixed_base else FLOATING_BASE_FAMILIES
    sr = screen(problem, robot, {}, fams, floating=not logs[0].fixed_base)
    w = weigh(logs, robot)
    return {"kind": "sgatwalk-sysid-calibration", "version": 2, "n_logs": len(logs),
            "weight": None if w is None else {"per_log_kg": list(w.per_log_kg), "mass_kg": w.mass_kg,
                                               "model_kg": w.model_kg},
            "fixed_base": logs[0].fixed_base, "base_state": source, "sigma": info["sigma"],
            "gap_rms": {nm: float(g) for nm, g in zip(names, gap)}, "rms": {nm: float(r) for nm, r in zip(names, rms)},
            "baseline_model": {t.label(): float(v) for t, v in base_model.items()},
            "screen": {t.label(): v for t, v in sr.selected.items()}}


def diagnose(logs: list[Log], *, calibration: dict | None = None, families=None, max_rounds: int = 3,
             progress=None, robot=None, base_model: dict | None = None, time_budget_s: float | None = 300.0,
             use_ground_truth: bool = False) -> dict:
    """Diagnose the sim against ``logs``; returns the report dict (see module docstring).

    The stages, in order: :func:`_prepare` (split into training and held-out windows, base
    model), :func:`_baseline` (nominal replay, noise floor), :func:`_localise` (where the nominal
    residual sits), :func:`_before` (held-out cost and RMS of the sim as it is), :func:`_select`
    (screening rounds, refit, family competition, pruning, backward elimination),
    :func:`_drop_negligible`, :func:`_roughness` (terrain roughness, a distribution fit),
    :func:`_intervals` (final refit, confidence intervals, identifiability), :func:`_vet` (Found vs
    uncertain / compensating), :func:`_check_roughness`
    and :func:`_roughness_effect`, :func:`_after` (residual left), :func:`_verdict`, :func:`_report`.

    Args:
        logs: recordings of the real robot (>= 2 for a held-out split by trajectory), all of one robot
            (``Log.robot``, from ``meta["robot"]``; n joints: the report has n per-joint channels).
        robot: that robot (``robots.RobotModel``); default the logs' own.
        calibration: output of :func:`calibrate` on "none" logs (engine gap: its baseline model
            is replayed under everything, its gap widens the noise floor; the sensor noise always
            comes from ``logs``), or None.
        families: family names to consider (default: the actuator families for fixed-base logs,
            the contact families and the torso's mass and centre of mass for floating-base logs:
            :data:`sysid.candidates.FLOATING_BASE_FAMILIES`).
        base_model: terms (Term -> value) kept fixed under every replay, e.g. the effects a
            fixed-base (in-air) diagnosis found, when stepping logs are diagnosed for contact
            (bottom-up staging, Bjelonic et al., arXiv:2509.06342). "Before" then means the sim with
            these terms.
        time_budget_s: no new screening round, family competition or elimination step starts
            after this many seconds (the report says so); None: no limit.
        max_rounds: screening/refit rounds (re-screening around the fitted model).
        progress: callable(str) for progress lines.
        use_ground_truth: replay floating-base logs from their ``gt.*`` ground-truth base state
            (``sgatwalk diagnose --use-ground-truth``). Default False: the logs' ``gt.*`` columns
            are ignored and every window starts from the state estimated from IMU, encoders and
            foot forces (:mod:`sysid.estimate`: flat ground, non-slipping stance foot, yaw 0), which
            is all a real robot has.

    Returns:
        The report: ``verdict``, ``noise_floor``, ``heldout_rms_before``, ``heldout_rms_after``
        [rad], ``effects`` (the findings: list of {family, joints, links, value, unit, ci95, ...}),
        ``uncertain`` (fitted terms that fail a test of :func:`_vet`, with ``reasons``),
        ``rejected``, ``indistinguishable``, ``residual``, ``localisation``, ``split``,
        ``base_state`` (:data:`sysid.data.BASE_FIXED`, ``BASE_ESTIMATED`` or ``BASE_GROUND_TRUTH``),
        ``noise`` (``sigma``: the logs' sensor noise, ``calibration_sigma``: the calibration's,
        for reference), ``model`` (term label -> value), ``runtime_s``, ``rollouts``,
        ``mujoco_warnings`` (MuJoCo's own warnings during the replays, counted by message:
        :data:`sysid.replay.MUJOCO_WARNINGS`), ``equivalent`` (effects named only as their class:
        :func:`_split_classes`; an effect in ``effects`` may carry ``not_excluded``, a nested excess
        these logs could not show), ``class_tests`` (every held-out test of :func:`_equivalence`) and
        ``weighing`` (floating-base logs with foot forces: what they weigh against the model,
        :meth:`sysid.weighing.Weighing.to_dict`; a torso mass it finds is the first effect, with
        ``"evidence": "weighing"``, and is in ``base_model``; else None).

    Raises:
        ValueError: a name in ``families`` is not a candidate family; ``robot`` is not the logs' robot;
            ``use_ground_truth`` with floating-base logs without ``gt.*`` columns.
    """
    clock = _Clock(time.perf_counter(), time_budget_s)
    warned = dict(MUJOCO_WARNINGS)
    say = progress or (lambda s: None)
    robot = _robot_of(logs, robot)
    logs, source = _replay_logs(logs, use_ground_truth)
    setup = _prepare(logs, families, calibration, base_model, say)
    setup, weighing = _weigh(logs, setup, calibration, robot, say)
    base = _baseline(logs, setup, calibration, robot)
    loc = _localise(logs, setup, base)
    problem = Problem(logs, setup.train, setup.heldout, base.floor, setup.with_imu, base=setup.base_model)
    before = _before(problem, base)
    sel = _select(problem, setup, before, base.names, robot, max_rounds, clock, say)
    final = _drop_negligible(problem, sel.model, sel.cost, before.c0)
    rough = _roughness(problem, setup, before.nothing, clock, say)
    eq = _equivalence(problem, final.model, final.cost, robot, clock, say)
    iv = _intervals(problem, eq.model, eq.cost, base.floor, robot, len(logs))
    indist = _identifiability(sel.confusable, iv.indistinguishable, iv.model, sel.ties)
    found, uncertain = _vet(problem, iv, robot, clock, say)
    found, equivalent = _split_classes(found, eq.decisions, robot)
    rough_rejected = _check_roughness(rough.fit, problem, iv.model, say)
    effects, indist = _roughness_effect(rough.fit, iv.model, found, indist)
    if weighing is not None and weighing.found:
        effects = [_weighed_effect(weighing, robot)] + effects
    after = _after(logs, problem, setup, base, before, iv.model)
    verdict = _verdict(before, after, effects, uncertain, base, rough.fit, calibration, source,
                       roughness_skipped=rough.budget_hit, equivalent=equivalent)
    rejected = sel.rejected + final.rejected + rough.rejected + rough_rejected + eq.rejected
    report = _report(logs, setup, base, loc, problem, before, sel, iv, effects, uncertain, indist, rejected, rough,
                     after, verdict, calibration, robot, clock, source)
    report["equivalent"] = equivalent
    report["class_tests"] = eq.tests
    report["weighing"] = None if weighing is None else weighing.to_dict()
    report["mujoco_warnings"] = {m: n - warned.get(m, 0) for m, n in MUJOCO_WARNINGS.items() if n > warned.get(m, 0)}
    return report


def fit_terms(logs: list[Log], start: dict, *, calibration: dict | None = None, base_model: dict | None = None,
              robot=None, use_ground_truth: bool = False) -> dict:
    """Fit given terms to ``logs`` on top of a base model, without screening or selection: the refit
    (bounded least squares, :func:`sysid.identify.refit`) of a diagnosis asked about named terms only.

    The logs are split and replayed as :func:`diagnose` replays them (training and held-out logs split
    by trajectory; floating-base logs in :data:`WINDOW_S` windows; the calibration's baseline model
    and ``base_model`` under every replay).

    Args:
        logs: recordings of the real robot (>= 2 for a held-out split).
        start: Term -> start value of the terms to fit (each within its family's bounds).
        calibration, base_model, robot, use_ground_truth: as for :func:`diagnose`.

    Returns:
        ``{"values": Term -> fitted value, "heldout_cost_before": C without the terms,
        "heldout_cost_after": C with them}`` (C: the diagnosis's held-out cost, Σ_channels
        mean((e/floor)²)).

    Raises:
        ValueError: ``start`` is empty or names a family that is not a candidate family; what
            :func:`diagnose` raises for the logs.
    """
    if not start:
        raise ValueError("fit_terms needs at least one term to fit")
    robot = _robot_of(logs, robot)
    logs, _ = _replay_logs(logs, use_ground_truth)
    setup = _prepare(logs, sorted({t.family for t in start}), calibration, base_model, lambda s: None)
    base = _baseline(logs, setup, calibration, robot)
    problem = Problem(logs, setup.train, setup.heldout, base.floor, setup.with_imu, base=setup.base_model)
    fit = refit(problem, dict(start))
    c = problem.cost([{}, fit.values], "heldout")
    return {"values": dict(fit.values), "heldout_cost_before": float(c[0]), "heldout_cost_after": float(c[1])}


# ------------------------------------------------------------------------------------------ stages
@dataclass
class _Clock:
    """Wall clock of one diagnosis and its time budget."""

    t_start: float  # time.perf_counter() when the diagnosis started [s]
    budget_s: float | None  # time budget [s]; None: no limit

    def over(self) -> bool:
        """Whether the time budget is spent (no new screening round, competition or elimination step)."""
        return self.budget_s is not None and time.perf_counter() - self.t_start > self.budget_s

    def elapsed(self) -> float:
        """Seconds since the start [s]."""
        return time.perf_counter() - self.t_start


@dataclass
class _Setup:
    """What :func:`_prepare` settles: replay mode, families, the train / held-out split, the base model."""

    fixed: bool  # fixed-base logs (single shooting) or floating-base (windowed replay)
    with_imu: bool  # torso roll/pitch [rad] and gyro [rad/s] compared too (floating base with an IMU)
    families: Sequence[str]  # candidate family names considered, as given (or the default tuple)
    train_idx: list[int]  # indices into ``logs`` of the training logs
    heldout_idx: list[int]  # indices into ``logs`` of the held-out logs
    split_note: str  # how the split was made, for the report
    train: list[Window]  # training windows (whole logs for fixed base, WINDOW_S windows otherwise)
    heldout: list[Window]  # held-out windows
    all_windows: list[Window]  # train + heldout, in that order
    base_model: dict  # Term -> value replayed under everything (calibration's baseline model, then ``base_model``)


@dataclass
class _Baseline:
    """The nominal replay (the sim under the base model) and the noise floor derived from it."""

    nominal: list[np.ndarray]  # per window of ``all_windows``: (1, L, k) predictions [rad, rad/s]
    floor: np.ndarray  # (k,) noise floor per channel [rad or rad/s], engine gap included when calibrated
    sigma: dict  # noise levels: encoders [rad], angle [rad], gyro [rad/s] (the latter two with an IMU)
    names: list[str]  # k channel names: the robot's n joints, then the IMU channels if any
    noise_floor: float  # RMS of the n joint floors [rad]
    floor_sq: float  # mean squared joint floor [rad²] (the gap-closed reference)


@dataclass
class _Before:
    """Fit quality of the sim before any candidate term (base model only)."""

    c0: float  # held-out cost C (dimensionless; = k when every channel sits at its floor)
    energy_train: np.ndarray  # (k,) training residual energy per channel [floor²]
    energy_heldout: np.ndarray  # (k,) held-out residual energy per channel [floor²]
    rms: float  # held-out joint RMS [rad]
    per_joint: np.ndarray  # (n,) held-out RMS per joint [rad]
    bic0: float  # training BIC of the empty model
    nothing: bool  # no joint's energy exceeds FLAG_ENERGY on training or held-out logs: nothing to explain


@dataclass
class _Step:
    """A model after one selection step."""

    model: dict  # Term -> value (each family's unit)
    cost: float  # held-out cost C of ``model`` (dimensionless)
    rejected: list[dict] = field(default_factory=list)  # rejection records made on the way, in report order
    budget_hit: bool = False  # the time budget stopped the step


@dataclass
class _Round:
    """One screening/refit round (:func:`_refit_round`)."""

    model: dict  # Term -> value: the round's candidate model (previous model + what it added)
    cost: float  # held-out cost C of ``model`` (dimensionless)
    kept: bool  # whether the round passed the held-out margin and the BIC test
    record: dict  # the round's entry of ``report["rounds"]``
    rejected: list[dict]  # rejection records (competition losers, pruned terms, the round's picks if not kept)
    ties: list = field(default_factory=list)  # (kept label, rival label, |cost difference|): near-equivalent fits


@dataclass
class _Selection:
    """Outcome of :func:`_select`: the model picked by screening, refit and elimination."""

    model: dict  # Term -> value
    cost: float  # held-out cost C of ``model`` (dimensionless)
    rounds: list[dict] = field(default_factory=list)  # ``report["rounds"]``
    screened: dict = field(default_factory=dict)  # column label -> first round it was screened in
    confusable: list = field(default_factory=list)  # (label a, label b, |corr|) from screening
    ties: list = field(default_factory=list)  # (label a, label b, |held-out cost difference|) from competition
    rejected: list[dict] = field(default_factory=list)  # rejection records, in report order
    budget_hit: bool = False  # the time budget stopped a round or an elimination step


@dataclass
class _RoughnessStage:
    """Outcome of :func:`_roughness`."""

    fit: RoughnessFit | None  # None: not attempted (nothing to explain, no IMU, not a family, or budget)
    rejected: list[dict] = field(default_factory=list)  # the roughness record when the fit does not declare it
    budget_hit: bool = False  # the time budget stopped the fit


@dataclass
class _Intervals:
    """Outcome of :func:`_intervals`: the final model with intervals and identifiability."""

    model: dict  # Term -> value after the final refit (kept only if it does not raise the held-out cost)
    cost: float  # held-out cost C of ``model`` (dimensionless)
    effects: list[dict]  # report entries (:func:`_entry` + ``heldout_cost_without``), most needed first
    indistinguishable: list[dict]  # pairs of fitted terms with |correlation| > 0.9
    terms: list = field(default_factory=list)  # the Term of each entry of ``effects``, same order


@dataclass
class _After:
    """The residual left by the final model."""

    rms: float  # held-out joint RMS [rad]
    per_joint: np.ndarray  # (n,) held-out RMS per joint [rad]
    energy: np.ndarray  # (k,) held-out residual energy per channel [floor²]
    gap_closed: float | None  # share of the excess mean-square over the floor removed; None at the floor
    localisation: dict  # :func:`sysid.stats.localisation` of all windows under base + model (no gravity)
    unexplained: list[str]  # joints whose RMS is still above sqrt(FLAG_ENERGY) floors


@dataclass
class _Verdict:
    """The verdict sentence and its warnings."""

    text: str
    warnings: list[str]


def _prepare(logs: list[Log], families, calibration: dict | None, base_model: dict | None,
             say: Callable[[str], None]) -> _Setup:
    """Check the families, split the logs into training and held-out windows, merge the base model.

    Fixed-base logs are replayed whole (single shooting), floating-base logs in WINDOW_S windows;
    a single log is cut at 60 % (train before, held-out after). The calibration's baseline model
    goes under ``base_model`` (``base_model`` wins on a shared term).

    Raises:
        ValueError: a name in ``families`` is not a candidate family.
    """
    fixed = logs[0].fixed_base
    with_imu = (not fixed) and all("angle" in lg.imu and "gyro" in lg.imu for lg in logs)
    if families is None:
        families = FIXED_BASE_FAMILIES if fixed else FLOATING_BASE_FAMILIES
    else:
        for f in families:
            if f not in FAMILIES:
                raise ValueError(f"unknown or unsupported candidate family {f!r}; supported: {', '.join(FAMILIES)}")
    tr_idx, ho_idx, split_note = split_by_trajectory(logs)
    if len(logs) == 1:
        n = len(logs[0])
        cut = int(0.6 * n)
        train, held = [Window(0, 0, cut)], [Window(0, cut, n)]
        if not fixed:
            train = [w for w in windows(logs, [0], WINDOW_S) if w.k1 <= cut]
            held = [w for w in windows(logs, [0], WINDOW_S) if w.k0 >= cut]
    elif fixed:
        train, held = whole_logs(logs, tr_idx), whole_logs(logs, ho_idx)
    else:
        train, held = windows(logs, tr_idx, WINDOW_S), windows(logs, ho_idx, WINDOW_S)
    say(f"{len(logs)} log(s): {split_note}; {'fixed base, single shooting' if fixed else f'floating base, {WINDOW_S} s windows'}")
    base = dict(base_model or {})
    if calibration and calibration.get("baseline_model"):
        from sysid.report import terms_from_labels

        base = {**terms_from_labels(calibration["baseline_model"]), **base}
    return _Setup(fixed=fixed, with_imu=with_imu, families=families, train_idx=tr_idx, heldout_idx=ho_idx,
                  split_note=split_note, train=train, heldout=held, all_windows=train + held, base_model=base)


def _weigh(logs: list[Log], setup: _Setup, calibration: dict | None, robot,
           say: Callable[[str], None]) -> tuple[_Setup, Weighing | None]:
    """The torso's mass from the weight on the feet (:func:`sysid.weighing.weigh`), on floating-base logs
    with foot forces: the weighing decides it, so ``link_mass`` (the root's only on a floating base)
    leaves the screened families, and a difference it finds goes into the base model every replay
    carries (the other effects are fitted around it) and into the findings (:func:`_weighed_effect`).
    The reference is the calibration logs' weighing when the calibration has one, else the model's
    mass. Fixed-base logs, a single log or logs without foot forces: ``setup`` unchanged and None."""
    if setup.fixed:
        return setup, None
    w = weigh(logs, robot, base_model=setup.base_model,
              reference_per_log_kg=((calibration or {}).get("weight") or {}).get("per_log_kg"))
    if w is None:
        return setup, None
    say(f"weight on the feet: {w.sentence()}; " + (f"{w.root} mass x{w.root_scale:.3f}" if w.found else "no mass difference"))
    base = dict(setup.base_model)
    if w.found:
        base[Term("link_mass", robot.root)] = w.root_scale
    return dataclasses.replace(setup, families=tuple(f for f in setup.families if f != "link_mass"),
                               base_model=base), w


def _weighed_effect(w: Weighing, robot) -> dict:
    """The report entry of a torso mass the weighing found (:func:`_weigh`): its interval is the weighing's."""
    e = _entry(Term("link_mass", robot.root), w.root_scale, w.root_scale_ci95, robot)
    e["where"] = (f"link {robot.root} (the root, weighed on the feet: {1000 * w.delta_kg:+.0f} g "
                  f"[{1000 * w.delta_ci95[0]:+.0f}, {1000 * w.delta_ci95[1]:+.0f}] against {w.reference})")
    e["evidence"] = "weighing"
    return e


def _baseline(logs: list[Log], setup: _Setup, calibration: dict | None, robot) -> _Baseline:
    """Replay all windows under the base model and estimate the noise floor from the residual.

    The floor (:func:`_floor`) is the encoder / IMU noise estimated from the nominal residual,
    widened by the calibrated engine gap where a calibration is given; never below MIN_FLOOR.
    """
    nominal = predict(logs, setup.all_windows, [setup.base_model], with_imu=setup.with_imu)
    floor, finfo = _floor(logs, setup.all_windows, nominal, setup.with_imu, calibration, robot)
    nj = len(robot.joint_names)
    return _Baseline(nominal=nominal, floor=floor, sigma=finfo["sigma"], names=_channel_names(robot, setup.with_imu),
                     noise_floor=float(np.sqrt(np.mean(floor[:nj] ** 2))), floor_sq=float(np.mean(floor[:nj] ** 2)))


def _localise(logs: list[Log], setup: _Setup, base: _Baseline) -> dict:
    """Where the nominal residual sits: per-channel statistics, groups and gait phases
    (:func:`sysid.stats.localisation`, with gravity torques from a replay model), for the report."""
    from sysid.model import Structure, replay_model

    rm = replay_model(Structure(fixed_base=setup.fixed, physics_dt=logs[0].physics_dt, robot=logs[0].robot_name))
    return localisation(logs, setup.all_windows, [p[0] for p in base.nominal], base.floor, base.names, rm.model,
                        rm.qadr, rm.dadr)


def _before(problem: Problem, base: _Baseline) -> _Before:
    """Held-out cost, residual energies, RMS and BIC of the empty model; whether anything needs explaining
    (a joint above FLAG_ENERGY floor² on training or held-out logs)."""
    c0 = float(problem.cost([{}], "heldout")[0])
    e_tr = problem.channel_energy(problem.predict([{}], "train"), "train")[0]
    e_ho = problem.channel_energy(problem.predict([{}], "heldout"), "heldout")[0]
    rms_before, per_before = problem.rms({}, "heldout")
    bic0 = _bic(problem, {}, 0)
    nothing = not flagged_joints(np.maximum(e_tr, e_ho), base.names)
    return _Before(c0=c0, energy_train=e_tr, energy_heldout=e_ho, rms=rms_before, per_joint=per_before, bic0=bic0,
                   nothing=nothing)


def _select(problem: Problem, setup: _Setup, before: _Before, names: list[str], robot, max_rounds: int,
            clock: _Clock, say: Callable[[str], None]) -> _Selection:
    """Screening rounds then family-level backward elimination (the selection rules of this module).

    Each round screens the residual around the current model (:func:`sysid.identify.screen`) and
    hands the picks to :func:`_refit_round`; rounds stop when screening picks nothing, a round is
    not kept, no joint is flagged any more, ``max_rounds`` is reached or the time budget is spent.
    With nothing to explain, returns the empty model at the cost ``before.c0``.
    """
    sel = _Selection(model={}, cost=before.c0)
    if before.nothing:
        say("no joint's residual energy exceeds 1.5x the noise floor's: nothing to explain")
        return sel
    for rnd in range(max_rounds):
        if clock.over():
            say("time budget reached: no further screening round")
            sel.budget_hit = True
            break
        # later screenings look for what the first left: fewer, smaller effects (the joint refit costs a
        # batched replay per term per iteration)
        sr = screen(problem, robot, sel.model, setup.families, floating=not setup.fixed,
                    max_terms=FIRST_SCREEN_TERMS if rnd == 0 else LATER_SCREEN_TERMS)
        say(f"round {rnd + 1}: flagged {', '.join(sr.flagged) or '-'}; screening picked "
            f"{', '.join(t.label() for t in sr.selected) or 'nothing'}")
        for lbl in sr.columns:
            sel.screened.setdefault(lbl, rnd + 1)
        sel.confusable.extend(sr.confusable)
        if not sr.selected:
            break
        rd = _refit_round(problem, sel.model, sel.cost, sr, setup.families, before.bic0, rnd + 1, robot, clock, say)
        sel.rejected.extend(rd.rejected)
        sel.ties.extend(rd.ties)
        sel.rounds.append(rd.record)
        if not rd.kept:
            break
        sel.model, sel.cost = rd.model, rd.cost
        if not flagged_joints(problem.channel_energy(problem.predict([sel.model], "train"), "train")[0], names):
            break
    elim = _eliminate_families(problem, sel.model, sel.cost, clock)
    sel.model, sel.cost = elim.model, elim.cost
    sel.rejected.extend(elim.rejected)
    sel.budget_hit = sel.budget_hit or elim.budget_hit
    merged = _merge_link_masses(problem, sel.model, sel.cost, robot, clock)
    sel.model, sel.cost = merged.model, merged.cost
    sel.rejected.extend(merged.rejected)
    return sel


def _chain_path(robot, a: str, b: str) -> list[str] | None:
    """Links from ``a`` to ``b`` inclusive when one is below the other in the kinematic tree (None otherwise)."""
    parent = {j.child: j.parent for j in robot.joints}

    def up(x: str, y: str) -> list[str] | None:
        """x, its parent, ... up to y; None when y is not above x."""
        path = [x]
        while path[-1] != y and path[-1] in parent:
            path.append(parent[path[-1]])
        return path if path[-1] == y else None

    if (path := up(a, b)) is not None:
        return path
    path = up(b, a)
    return path[::-1] if path is not None else None


def _merge_link_masses(problem: Problem, model: dict, cost: float, robot, clock: _Clock) -> _Step:
    """Parsimony for link masses: two mass terms on one chain (e.g. thigh and ankle) can stand in
    for one mass error on a link between them (the tibia): their loads on the joints above add up
    to nearly the same torques, and the greedy screening adds the two one at a time without ever
    trying the link between. For every such pair, each link on the path between them (ends
    included) replaces the pair as one term, refitted with the rest; the best single term is kept
    if it fits the held-out logs within the selection margin of the pair (one parameter instead of
    two, the pair's extra freedom not needed). Pairs are tried in order of their link names; a
    replacement is recorded with both costs."""
    k = problem.k
    step = _Step(model=dict(model), cost=cost)
    done: set = set()
    while not clock.over():
        masses = sorted((t for t in step.model if t.family == "link_mass"), key=lambda t: t.target)
        pair = next(((a, b, path) for i, a in enumerate(masses) for b in masses[i + 1:]
                     if (a, b) not in done and (path := _chain_path(robot, a.target, b.target))), None)
        if pair is None:
            break
        a, b, path = pair
        done.add((a, b))
        rest = {t: v for t, v in step.model.items() if t not in (a, b)}
        best = None
        for ln in path:
            t = Term("link_mass", ln)
            if t in rest:
                continue
            start = {**rest, t: float(np.clip(0.5 * (step.model[a] + step.model[b]), *term_bounds(t, robot)))}
            fit = refit(problem, start, grid=False, max_nfev=6)
            c = float(problem.cost([fit.values], "heldout")[0])
            if best is None or c < best[1]:
                best = (t, c, dict(fit.values))
        if best is not None and best[1] - step.cost < _margin(step.cost, k):
            t, c, vals = best
            for u in (a, b):
                step.rejected.append({"term": u.label(), "family": "link_mass", "value": step.model[u],
                                      "reason": f"{a.label()} and {b.label()} replaced by one mass term on the link "
                                                f"between, {t.label()} x{vals[t]:.3f}: it fits the held-out logs as "
                                                f"well (cost {c:.1f} vs {step.cost:.1f}) with one parameter"})
            step.model, step.cost = vals, c
    return step


#: Least-squares evaluations of the joint refit after each screening (:func:`_refit_round`; each one
#: batched replay).
REFIT_NFEV = 8
#: Most terms the first screening may pick, and each later one (:func:`_select`).
FIRST_SCREEN_TERMS, LATER_SCREEN_TERMS = 6, 3


def _refit_round(problem: Problem, model: dict, cost: float, sr: ScreenResult, families, bic0: float, rnd: int,
                 robot, clock: _Clock, say: Callable[[str], None]) -> _Round:
    """Refit the screening picks with the current model, let rival families compete on the same
    joints (:func:`_compete`, skipped once the budget is spent), prune terms on held-out data
    (:func:`_prune_terms`), name the servo and friction forms (:func:`servo_forms`,
    :func:`friction_forms`), and decide: the round is kept if it lowers the held-out cost by the
    margin and the training BIC by more than 10.

    Args:
        model, cost: the current model (Term -> value) and its held-out cost.
        sr: this round's screening.  bic0: training BIC of the empty model.  rnd: round number (1-based).
    """
    k = problem.k
    fit = refit(problem, {**model, **sr.selected}, max_nfev=REFIT_NFEV)
    cand = dict(fit.values)
    cand, swaps, ties = _compete(problem, model, cand, sr, families, k, robot) if not clock.over() else (cand, [], [])
    for sw in swaps:
        say(f"round {rnd}: {sw['reason']}")
    cand, pruned = _prune_terms(problem, model, cand)
    cand, merged = servo_forms(problem, cand)
    for m in merged:
        say(f"round {rnd}: {m['reason']}")
    cand, added = friction_forms(problem, cand) if not clock.over() else (cand, [])
    for a in added:
        say(f"round {rnd}: {a['term']} {a['reason']}")
    rejected = list(swaps) + pruned + merged
    c_new = float(problem.cost([cand], "heldout")[0]) if cand else cost
    bic_new = _bic(problem, cand, len(cand))
    bic_old = _bic(problem, model, len(model)) if model else bic0
    kept = bool(cand) and (cost - c_new >= _margin(cost, k)) and (bic_old - bic_new > 10)
    record = {"round": rnd, "flagged": sr.flagged, "picked": [t.label() for t in sr.selected],
              "heldout_cost_before": cost, "heldout_cost_after": c_new, "kept": kept}
    say(f"round {rnd}: held-out cost {cost:.1f} -> {c_new:.1f} (floor {k}); {'kept' if kept else 'rejected'}")
    if not kept:
        for t in sr.selected:
            if t in cand and t not in model:
                rejected.append({"term": t.label(), "family": t.family, "value": cand[t],
                                 "reason": "the round did not improve held-out trajectories enough"})
    return _Round(model=cand, cost=c_new, kept=kept, record=record, rejected=rejected, ties=ties)


def servo_forms(problem: Problem, model: dict) -> tuple[dict, list[dict]]:
    """Name the form of each servo whose kp and kd were both fitted (``pd_gain`` and ``kd_gain`` on one
    joint, :data:`sysid.identify.JOINT_BLOCKS`): kp and kd scaled together (``torque_constant``, one
    parameter: a motor torque-constant, current-gain or supply-voltage error; fitted through
    ``mujoco.sysid``, :func:`sysid.mjsysid.fit`, where the joint has no series hinge) replaces the pair when
    its refit fits the held-out logs within the selection margin of the pair; otherwise both stay (kp
    and kd off by different factors). A kp-only or kd-only error needs nothing here: the term the
    fit does not need is pruned before (:func:`_prune_terms`).

    Returns:
        (the model Term -> value, records of the pairs replaced).
    """
    k = problem.k
    out = dict(model)
    records = []
    pairs = sorted({t.target for t in out if t.family == "pd_gain"} & {t.target for t in out if t.family == "kd_gain"})
    if not pairs:
        return out, records
    c_pair = float(problem.cost([out], "heldout")[0])
    for j in pairs:
        kp, kd = Term("pd_gain", j), Term("kd_gain", j)
        tc = Term("torque_constant", j)
        if tc in out:
            continue
        rest = {u: v for u, v in out.items() if u not in (kp, kd)}
        start = float(np.clip(math.sqrt(out[kp] * out[kd]), *term_bounds(tc, problem.robot)))
        if any(u.family in PLAY_FAMILIES + ("joint_compliance",) and u.target == j for u in rest):
            fit = refit(problem, {**rest, tc: start}, free=[tc], grid=False, max_nfev=8)
        else:  # kp and kd as one mujoco.sysid parameter (apply_pdgain), its optimizer (mujoco.minimize)
            from sysid.mjsysid import fit as mjsysid_fit

            fit = mjsysid_fit(problem, {**rest, tc: start}, [tc], max_iters=8)
        c_tc = float(problem.cost([fit.values], "heldout")[0])
        if c_tc - c_pair < _margin(c_pair, k):
            records.append({"term": f"{kp.label()},{kd.label()}", "family": "pd_gain", "value": out[kp],
                            "reason": f"kp x{out[kp]:.3f} and kd x{out[kd]:.3f} at {j} are one torque-constant "
                                      f"error x{fit.values[tc]:.3f} (kp and kd together): held-out cost {c_tc:.1f} "
                                      f"vs {c_pair:.1f} with both free"})
            out, c_pair = dict(fit.values), c_tc
    return out, records


#: The two terms of a joint's Coulomb-viscous friction (BAM's model M1, M. Duclusaud et al., ICRA 2025,
#: arXiv:2410.08650): a joint whose model holds one of them is refitted with the other beside it
#: (:func:`friction_forms`).
FRICTION_PAIR = ("coulomb_friction", "viscous_damping")


def friction_forms(problem: Problem, model: dict) -> tuple[dict, list[dict]]:
    """Complete each joint's friction to BAM's Coulomb-viscous form (M1, :data:`FRICTION_PAIR`): where the
    model holds a Coulomb friction and no viscous damping at a joint (or the reverse), the other term is
    fitted beside it (both free, the rest of the model fixed) and kept when it lowers the held-out cost
    by the selection margin, away from its family's bounds. Screening sees one family per joint at a
    time, and a linearisation around dry friction hides the viscous share that only shows at speed.

    Returns:
        (the model Term -> value, records of the terms added: ``{"term", "family", "value", "reason"}``).
    """
    out = dict(model)
    records = []
    friction = sorted(u for u in model if u.family in FRICTION_PAIR)
    if not friction:  # nothing to complete: no held-out replay
        return out, records
    cost = float(problem.cost([out], "heldout")[0])
    for t in friction:
        other = Term(FRICTION_PAIR[1 - FRICTION_PAIR.index(t.family)], t.target)
        if other in out or t not in out or not term_allowed(other, problem.robot):
            continue
        fit = refit(problem, {**out, other: float(term_probe(other, problem.robot))}, free=[t, other], grid=False,
                    max_nfev=8)
        c = float(problem.cost([fit.values], "heldout")[0])
        if cost - c >= _margin(cost, problem.k) and not _at_bound(other, fit.values[other], problem.robot):
            records.append({"term": other.label(), "family": other.family, "value": fit.values[other],
                            "reason": f"added beside {t.label()} (Coulomb and viscous friction together, BAM's M1): "
                                      f"held-out cost {cost:.1f} -> {c:.1f}"})
            out, cost = dict(fit.values), c
    return out, records


def _prune_terms(problem: Problem, model: dict, cand: dict) -> tuple[dict, list[dict]]:
    """Term-level pruning of a round's candidate on held-out data (one batched replay, no refit):
    new terms whose removal raises the held-out cost by less than the margin go, then terms within
    their family's smallest reported effect; the rest is refitted briefly if anything went.

    Returns:
        (the pruned candidate Term -> value, rejection records in that order).
    """
    k = problem.k
    rejected = []
    terms = list(cand)
    sets = [cand] + [{u: v for u, v in cand.items() if u != t} for t in terms]
    costs = problem.cost(sets, "heldout")
    c_with = float(costs[0])
    drop = [t for t, c in zip(terms, costs[1:]) if c - c_with < _margin(c_with, k) and t not in model]
    for t in drop:
        rejected.append({"term": t.label(), "family": t.family, "value": cand[t],
                         "reason": f"removing it changes the held-out cost by {float(costs[1 + terms.index(t)] - c_with):+.2f} "
                                   f"(< {_margin(c_with, k):.2f}): not needed"})
        cand.pop(t)
    small = _below_min_effect(cand, problem.robot)
    for t in small:
        rejected.append(_small_entry(t, cand.pop(t), problem.robot))
    drop += small
    if drop and cand:
        fit = refit(problem, cand, grid=False, max_nfev=6)
        cand = dict(fit.values)
    return cand, rejected


def _eliminate_families(problem: Problem, model: dict, cost: float, clock: _Clock) -> _Step:
    """Family-level backward elimination: with more than one family in ``model``, each family in
    name order is removed and the rest refitted; it goes if the held-out cost rises by less than
    the margin. Stops when the time budget is spent (``budget_hit`` in the returned step)."""
    k = problem.k
    step = _Step(model=model, cost=cost)
    fams = sorted({t.family for t in model})
    if len(fams) > 1:
        for f in fams:
            if clock.over():
                step.budget_hit = True
                break
            rest = {t: v for t, v in step.model.items() if t.family != f}
            fit = refit(problem, rest, grid=False, max_nfev=6)
            c_wo = float(problem.cost([fit.values], "heldout")[0])
            if c_wo - step.cost < _margin(step.cost, k):
                for t in step.model:
                    if t.family == f:
                        step.rejected.append({"term": t.label(), "family": f, "value": step.model[t],
                                              "reason": f"backward elimination: without {f} (rest refitted) the "
                                                        f"held-out cost changes by {c_wo - step.cost:+.2f}"})
                step.model, step.cost = dict(fit.values), c_wo
    return step


def _drop_negligible(problem: Problem, model: dict, cost: float, c0: float) -> _Step:
    """Drop terms a later refit moved to within their family's smallest reported effect of nominal,
    refit the rest briefly and recompute the held-out cost (``c0`` when nothing is left)."""
    step = _Step(model=model, cost=cost)
    small = _below_min_effect(step.model, problem.robot)
    if small:  # a refit can move an earlier term to within the smallest reported effect of nominal
        for t in small:
            step.rejected.append(_small_entry(t, step.model.pop(t), problem.robot))
        if step.model:
            step.model = dict(refit(problem, step.model, grid=False, max_nfev=6).values)
        step.cost = float(problem.cost([step.model], "heldout")[0]) if step.model else c0
    return step


def _roughness(problem: Problem, setup: _Setup, nothing: bool, clock: _Clock,
               say: Callable[[str], None]) -> _RoughnessStage:
    """Terrain roughness: a distribution of surfaces fitted to what the deterministic model leaves
    (:func:`sysid.roughness.fit_roughness`), on floating-base logs with an IMU when
    ``terrain_roughness`` is a considered family and there is something to explain. Adds the fit's
    rollouts to ``problem.n_rollouts``."""
    out = _RoughnessStage(fit=None)
    if not nothing and setup.with_imu and "terrain_roughness" in setup.families:
        if clock.over():
            out.budget_hit = True
        else:
            from sysid.roughness import fit_roughness

            # fitted on the residual *before* the deterministic contact terms: on uneven ground a
            # contact term absorbs part of the surface's signature in the training logs (measured: foot
            # friction 1.34 fitted on 11 mm bumps in PyBullet, the roughness left 3 mm)
            say("terrain roughness: simulating the logs on random surfaces (distribution fit)")
            rough = fit_roughness(problem, {})
            problem.n_rollouts += rough.n_rollouts
            say(f"terrain roughness: RMS height {1000 * rough.rms_height:.2f} mm; "
                f"{'declared' if rough.declared else 'rejected'}: {rough.reason}")
            if not rough.declared:
                out.rejected.append({"term": "terrain_roughness", "family": "terrain_roughness",
                                     "value": rough.rms_height, "reason": rough.reason})
            out.fit = rough
    return out


def _intervals(problem: Problem, model: dict, cost: float, floor: np.ndarray, robot, n_logs: int) -> _Intervals:
    """Final refit, 95 % intervals and identifiability of the selected model.

    The final refit is kept only if it does not raise the held-out cost. Intervals come from
    :func:`sysid.identify.confidence` with the training residual's integrated autocorrelation and,
    with more than one log, the spread of per-log refits (:func:`_trajectory_spread`), plus the
    model-form bound of :func:`sysid.identify.discrepancy_bound`. Each effect
    records how much worse the held-out cost gets without it; effects are sorted by that, and
    term pairs with |correlation| > 0.9 are listed as indistinguishable. An empty model returns empty lists.
    """
    effects, indist, terms_of = [], [], []
    # a shape parameter goes with its effect: one left without it (its effect replaced) is dropped
    model = {t: v for t, v in model.items() if t.family not in SHAPE_FAMILIES or _shape_owner(t) in model}
    if model:
        fit = refit(problem, model, grid=False, max_nfev=4)
        if float(problem.cost([fit.values], "heldout")[0]) <= cost:
            model = dict(fit.values)
            cost = float(problem.cost([model], "heldout")[0])
        preds = problem.predict([model], "train")
        res = [(m - p[0]) / floor for m, p in zip(problem.meas["train"], preds)]
        tau = integrated_autocorr(res)
        spread = _trajectory_spread(problem, model) if n_logs > 1 else {}
        ci, corr = confidence(fit, problem, tau, spread=spread, spread_dof=n_logs - 1 if spread else None)
        order = sorted((u for u in model if u.family not in SHAPE_FAMILIES), key=lambda u: (u.family, u.target or ""))
        c_drop = problem.cost([model] + [{u: v for u, v in model.items() if u != t} for t in order], "heldout")
        pairs = []
        for t, cd in zip(order, c_drop[1:]):
            e = _entry(t, model[t], ci.get(t), robot)
            e["heldout_cost_without"] = float(cd - c_drop[0])  # how much worse held-out gets without it
            for u in model:
                if u.family in SHAPE_FAMILIES and _shape_owner(u) == t:
                    lo, hi = ci.get(u, (None, None))
                    e["shape"] = {u.family: {"value": float(model[u]), "unit": u.fam.unit,
                                             "ci95": [None if lo is None else float(lo), None if hi is None else float(hi)]}}
                    e["display"] += f", falling away over {u.fam.fmt(model[u])}"
            pairs.append((t, e))
        pairs.sort(key=lambda te: -te[1]["heldout_cost_without"])
        terms_of = [t for t, _ in pairs]
        effects = [e for _, e in pairs]
        terms = fit.terms
        for i in range(len(terms)):
            for j in range(i + 1, len(terms)):
                if abs(corr[i, j]) > 0.9:
                    indist.append({"a": terms[i].label(), "b": terms[j].label(), "corr": float(corr[i, j]),
                                   "experiment": _experiment(terms[i].family, terms[j].family)})
    return _Intervals(model=model, cost=cost, effects=effects, indistinguishable=indist, terms=terms_of)


def _shape_owner(t: Term) -> Term:
    """The effect a shape parameter belongs to (a Stribeck velocity's Stribeck friction at its joint)."""
    return Term("stribeck_friction", t.target)


def _identifiability(confusable: list, indist: list[dict], model: dict, ties: list = ()) -> list[dict]:
    """``indist`` plus the family competition's near-equivalent fits (``ties``: another family on the
    same joint fitted the held-out logs within the margin) and the screening's confusable column
    pairs, each whose first member is in ``model`` (not already listed), each with the experiment
    that would tell them apart. Returns a new list."""
    indist = list(indist)
    labels = {t.label() for t in model}
    for a, b, d in ties:
        if a in labels and not any({e["a"], e["b"]} == {a, b} for e in indist):
            indist.append({"a": a, "b": b, "corr": None, "heldout_cost_difference": float(d),
                           "why": "both fit the held-out logs within the selection margin",
                           "experiment": _experiment(a.split("[")[0], b.split("[")[0])})
    for a, b, c in confusable:
        fa, fb = a.split("[")[0], b.split("[")[0]
        if any({e["a"], e["b"]} == {a.replace("(-)", ""), b.replace("(-)", "")} for e in indist):
            continue
        if any(t.label() == a.replace("(-)", "") for t in model):
            indist.append({"a": a.replace("(-)", ""), "b": b.replace("(-)", ""), "corr": c,
                           "experiment": _experiment(fa, fb.split("(")[0])})
    return indist


#: A fitted value within this share of its family's range from a bound is "at a bound" (:func:`_vet`).
BOUND_TOL = 0.01
#: A term whose held-out need is below this share of the need of a stronger term on the same joint is a
#: small correction beside that term (:func:`_vet`, rule "compensating").
COMPENSATION_SHARE = 0.1


def _series_parts(a: str, b: str) -> bool:
    """Whether families ``a`` and ``b`` are the two parts of one transmission in series: a spring
    (``joint_compliance``) and a gear play (:data:`sysid.candidates.PLAY_FAMILIES`), the dead-zone model of
    a gear pair (M. Nordin and P.-O. Gutman, "Controlling mechanical systems with backlash: a survey",
    Automatica 38(10), 2002). Neither is a small correction of the other: removing the spring from a
    model that holds the play costs far more than the play's own need, whatever the play's size, so the
    share rule of :func:`_vet` does not compare them (the refit rule still does)."""
    return "joint_compliance" in (a, b) and (a in PLAY_FAMILIES or b in PLAY_FAMILIES)


def _loaded_joints(t: Term, robot) -> set:
    """The joints a term acts on: its joint, or for a link term the (up to 3) joints its mass loads."""
    if t.fam.scope == "joint":
        return {t.target}
    if t.fam.scope == "link":
        return set(joints_above(robot, t.target)[:3])
    return set()


def _vet(problem: Problem, iv: _Intervals, robot, clock: _Clock,
         say: Callable[[str], None]) -> tuple[list[dict], list[dict]]:
    """Split the fitted effects into "Found" and "uncertain / compensating" (no invented physics).

    A term is Found only if all of these hold (each failure is a reason, in the entry's ``reasons``):

    * it survives held-out elimination: removing it raises the held-out cost by at least the
      selection margin (``heldout_cost_without``);
    * its 95 % interval excludes the sim's (nominal) value;
    * it is not at a bound of its family (within :data:`BOUND_TOL` of the range): a value the fit
      could not take further says the family is the wrong shape, not what the value is;
    * it does not only compensate another term: with more than one term, the others refitted without
      it must not explain the held-out logs as well (cost rise below the margin), and its held-out
      need must not be below :data:`COMPENSATION_SHARE` of a stronger term's on the same joint
      (a small correction riding on that term's model-form error; a spring and a play at one joint,
      the two parts of one transmission, are not compared so: :func:`_series_parts`).

    The terms all stay in the identified model (``report["model"]``: they lower the held-out error);
    only the claim of physics is withheld. Returns (found, uncertain), both lists of report entries
    (uncertain ones with ``reasons``), each sorted by held-out need.
    """
    margin = _margin(iv.cost, problem.k)
    effects = [dict(e) for e in iv.effects]
    reasons: list[list[str]] = [[] for _ in effects]
    places = [_loaded_joints(t, robot) for t in iv.terms]
    for i, (e, t) in enumerate(zip(effects, iv.terms)):
        need = e["heldout_cost_without"]
        if need < margin:
            reasons[i].append(f"the final model without it fits the held-out logs about as well "
                              f"(cost {need:+.2f}, margin {margin:.2f})")
        lo, hi = e["ci95"]
        if lo is None or hi is None or not (math.isfinite(lo) and math.isfinite(hi)):
            reasons[i].append("its value is not identifiable with this data (unbounded interval)")
        elif lo <= e["nominal"] <= hi:
            reasons[i].append(f"its 95 % interval holds the sim's value ({t.fam.fmt(e['nominal'])})")
        blo, bhi = term_bounds(t, robot)
        tol = BOUND_TOL * (bhi - blo)
        if e["value"] - blo <= tol or bhi - e["value"] <= tol:
            reasons[i].append(f"it sits at the bound of its family ({t.fam.fmt(blo if e['value'] - blo <= tol else bhi)}): "
                              "the family's shape does not fit, so the value means little")
        for j, o in enumerate(effects):
            if (j != i and places[i] & places[j] and o["heldout_cost_without"] > need
                    and need < COMPENSATION_SHARE * o["heldout_cost_without"]
                    and not _series_parts(t.family, iv.terms[j].family)):
                reasons[i].append(f"a small correction beside {o['words']} at {o['where']} (held-out need "
                                  f"{need:.2f} vs {o['heldout_cost_without']:.2f}): it compensates that term")
                break
    if len(iv.model) > 1:
        for i, (e, t) in enumerate(zip(effects, iv.terms)):
            if reasons[i] or clock.over():  # already not a finding: no refit needed to say so
                continue
            rest = {u: v for u, v in iv.model.items() if u != t}
            fit = refit(problem, rest, grid=False, max_nfev=6)
            rise = float(problem.cost([fit.values], "heldout")[0]) - iv.cost
            e["heldout_cost_without_refit"] = rise
            if rise < margin:
                reasons[i].append(f"the other terms, refitted without it, explain the held-out logs as well "
                                  f"(cost {rise:+.2f}, margin {margin:.2f}): it only compensates them")
    found = [e for e, r in zip(effects, reasons) if not r]
    uncertain = [{**e, "reasons": r} for e, r in zip(effects, reasons) if r]
    for e in uncertain:
        say(f"uncertain: {e['words']} {e['display']} at {e['where']}: {'; '.join(e['reasons'])}")
    return found, uncertain


@dataclass
class _Equivalence:
    """Outcome of :func:`_equivalence`."""

    model: dict  # Term -> value: the model with each tested effect's winner in place
    cost: float  # held-out cost C of ``model`` (dimensionless)
    decisions: list[dict] = field(default_factory=list)  # one per tested effect (see _equivalence)
    tests: list[dict] = field(default_factory=list)  # every held-out test made, for the report
    rejected: list[dict] = field(default_factory=list)  # effects replaced by a rival that fits better


def _effect_groups(terms: list[Term], robot) -> list[tuple[str, list[Term]]]:
    """Found terms grouped into effects: a centre-of-mass offset's axes on one link are one effect,
    every other term is its own. Returns [(family, terms)] in the order of ``terms``."""
    out: list[tuple[str, list[Term]]] = []
    for t in terms:
        if t.family == "link_com":
            g = next((grp for f, grp in out if f == "link_com" and term_link(grp[0]) == term_link(t)), None)
            if g is not None:
                g.append(t)
                continue
        out.append((t.family, [t]))
    return out


def _equivalence(problem: Problem, model: dict, cost: float, robot, clock: _Clock,
                 say: Callable[[str], None]) -> _Equivalence:
    """The honest-equivalence rule: each selected effect against the best fit of every other family of
    its classes (:mod:`sysid.equivalence`), at the same place, on the held-out logs.

    For each effect of ``model`` whose removal raises the held-out cost by at least the selection
    margin (strongest first; run whatever the time budget: naming depends on it), every rival family
    (:func:`sysid.equivalence.rival_families`) is fitted in its place (the effect's terms removed, the
    rival's terms fitted, grid starts for non-smooth families, the rest of the model kept; a Stribeck
    friction is fitted beside the Coulomb term it rivals, whose static excess it is: BAM's nested
    comparison, with the joint's damping refitted beside them; a rival gear play replaces the play the
    model already holds at that joint, since one joint holds one play). The candidate with the lowest
    held-out cost is the winner (one fitted at a bound of its family only if no other comes within the
    margin of it; a Stribeck friction over the Coulomb friction it nests only if it beats it by the
    margin: parsimony, and otherwise listed as not excluded beside it), and the model keeps it. A
    candidate fitted at a bound is otherwise no candidate (a distorted form), except a nested excess
    fitted to zero, which is tested at its probe size beside the winner: could these logs show it? If
    not, the winner (the excess's own restriction, i.e. the nested rival's best fit) stands and the
    excess is listed as not excluded (``not_excluded``: [{family, terms at the probe size, segment, experiment}]). The winner is
    named (status ``"found"``) only if it beats every other candidate beyond the noise
    (:func:`sysid.equivalence.heldout_test`) and by at least the selection margin of this module (a
    difference the noise cannot make but smaller than what selection counts is a model-form detail
    both share, not evidence for one form); otherwise the effect is reported as its class
    (status ``"class"``) with the candidates the test cannot separate from the winner and the
    excitation segment that would.

    Returns:
        :class:`_Equivalence`: ``decisions`` are dicts with ``terms`` (the winner's Terms), ``status``,
        ``family`` (the winner's), ``candidates`` ([{family, terms: {label: value}, heldout_cost,
        z}] within the noise of the winner, the winner first), ``words`` (the class), ``segment`` and
        ``experiment`` (what tells the first rival apart), ``joint`` (the place). A winner that is not
        the tested family is tested against its own classes in turn (one level), and that decision
        stands. ``clock`` is not consulted: naming depends on this test, whatever the time budget.
    """
    from sysid.equivalence import class_words, heldout_test, place_joint, rival_families, rival_terms, separating

    out = _Equivalence(model=dict(model), cost=cost)
    order = sorted(model, key=lambda u: (u.family, u.target or ""))
    if not order:
        return out
    margin = _margin(cost, problem.k)
    c_drop = problem.cost([{u: v for u, v in model.items() if u != t} for t in order], "heldout")
    need = {t: float(c) - cost for t, c in zip(order, c_drop)}
    tested = [t for t in sorted(order, key=lambda u: -need[u]) if need[t] >= margin]
    queue = [(fam, grp, 0) for fam, grp in _effect_groups(tested, robot)]
    while queue:
        fam, grp, depth = queue.pop(0)
        rivals = rival_families(fam)
        if not rivals:
            continue
        if any(t not in out.model for t in grp):
            continue
        base_vals = dict(out.model)
        rest = {u: v for u, v in base_vals.items() if u not in grp}
        nested = {u for u in grp if u.family == "coulomb_friction"}  # Stribeck's excess is beside a Coulomb level
        cands = [{"family": fam, "values": base_vals, "terms": list(grp)}]
        rival_sets, replaced = {}, {}
        for g in rivals:
            rts = [u for u in rival_terms(grp[0], g, robot) if u not in rest]
            if not rts:
                continue
            rival_sets[g] = rts
            # one joint holds one gear play: a rival play replaces the play the model has there (a series
            # spring beside a dead band is tested against motor-side play in place of both)
            drop = [v for v in rest if v.family in PLAY_FAMILIES
                    and any(u.family in PLAY_FAMILIES and u.target == v.target for u in rts)]
            if drop:
                replaced[g] = drop
        # a Stribeck excess rivals a Coulomb term beside it (nested), and a replacing play takes another
        # term with it: no linearised probe on ``rest`` shows what they add, so they are always fitted
        always = [g for g in rival_sets if (nested and g == "stribeck_friction") or g in replaced]
        plausible = _plausible_rivals(problem, base_vals, rest,
                                      {g: r for g, r in rival_sets.items() if g not in always}, robot)
        plausible += always
        for g in plausible:
            rts = rival_sets[g]
            # Stribeck's excess is fitted with the Coulomb level it sits on and the joint's damping beside
            # them (BAM's M2 holds a viscous term: the excess trades against it at low speed)
            keep = ({u: base_vals[u] for u in base_vals
                     if u in nested or (u.family in DAMPING_FAMILIES and u.target in {n.target for n in nested})}
                    if g == "stribeck_friction" else {})
            # a Stribeck friction is fitted with its Stribeck velocity (BAM's M2), from two starts: the
            # library's default and a slower fall-off (the fit is not convex in it)
            shape = [Term("stribeck_velocity", u.target) for u in rts if u.family == "stribeck_friction"]
            start = {**{u: v for u, v in rest.items() if u not in replaced.get(g, ())}, **keep,
                     **{u: float(term_probe(u, robot)) for u in rts}}
            try:
                fits = [refit(problem, {**start, **{u: v0 for u in shape}}, free=rts + list(keep) + shape, max_nfev=6)
                        for v0 in ((STRIBECK_VELOCITY, SLOW_STRIBECK_START) if shape else (None,))]
            except ValueError:  # a rival this robot's model cannot hold (e.g. a structure clash): not a candidate
                continue
            fit = min(fits, key=lambda f: f.cost)
            cands.append({"family": g, "values": dict(fit.values), "terms": rts + list(keep), "own": rts,
                          "replaces": replaced.get(g, []), "nests": bool(keep)})
        if len(cands) == 1:
            continue
        costs = problem.cost([c["values"] for c in cands], "heldout")
        for c, cc in zip(cands, costs):
            c["heldout_cost"] = float(cc)
            c["at_bound"] = any(_at_bound(u, c["values"][u], robot) for u in c.get("own", c["terms"]))
        gap = _margin(float(np.min(costs)), problem.k)
        win = _winner(cands, costs, gap)
        w = cands[win]
        tied, unresolved = [w], []
        for i, c in enumerate(cands):
            if i == win:
                continue
            vals = c["values"]
            if c["at_bound"]:
                own = c.get("own", c["terms"])
                nested_zero = own != c["terms"] and all(
                    abs(c["values"][u] - u.fam.nominal) <= BOUND_TOL * np.subtract(*term_bounds(u, robot)[::-1])
                    for u in own)
                if not nested_zero:
                    continue  # at a bound of its family: a distorted form, no candidate
                # fitted to nothing (a nested excess at zero: it reduces to the winner): could the logs show
                # it at a typical size? Tested there, beside the winner's model
                vals = {**w["values"], **{u: float(term_probe(u, robot)) for u in own}}
                c["probed"] = True
            ht = heldout_test(problem, w["values"], vals)
            c["z"] = ht.z
            apart = ht.a_better and ht.cost_b - ht.cost_a >= gap
            out.tests.append({"effect": ",".join(t.label() for t in grp), "winner": w["family"], "rival": c["family"],
                              "winner_cost": ht.cost_a, "rival_cost": ht.cost_b, "z": ht.z, "z_crit": ht.z_crit,
                              "tau": ht.tau, "margin": gap, "apart": apart})
            if not apart and (c.get("probed") or (c.get("nests") and win == 0)):
                # a nested excess the fit put at zero that these logs could not show at its probe size, or
                # one fitted beside the winner that does not beat it by the margin: the winner is that
                # form's own restriction, so it stands (parsimony); the excess is reported as not
                # excluded, with the segment that would show it
                seg_n, text_n = separating(w["family"], c["family"])
                own = c.get("own", c["terms"])
                unresolved.append({"family": c["family"], "terms": {u.label(): float(vals[u]) for u in own},
                                   "segment": seg_n, "experiment": text_n})
            elif not apart:
                tied.append(c)
        joint = place_joint(grp[0], robot)
        status = "found" if len(tied) == 1 else "class"
        if win != 0:
            out.model = dict(w["values"])
            out.cost = w["heldout_cost"]
            for t in list(grp) + list(w.get("replaces", [])):
                cmp = f"cost {w['heldout_cost']:.1f} vs {cands[0]['heldout_cost']:.1f}"
                out.rejected.append({"term": t.label(), "family": t.family, "value": base_vals[t],
                                     "reason": f"{w['family']} in its place fits the held-out logs better ({cmp})"
                                     if status == "found" or t not in grp or all(c is not cands[0] for c in tied)
                                     else f"{w['family']} in its place fits the held-out logs as well ({cmp}): "
                                          "the two are named as a class"})
        seg, text = separating(w["family"], tied[1]["family"]) if len(tied) > 1 else (None, None)
        dec = {"terms": w["terms"], "status": status, "family": w["family"], "joint": joint,
               "not_excluded": unresolved,
               "words": class_words(w["family"], tied[1]["family"]) if len(tied) > 1 else None,
               "segment": seg, "experiment": text,
               "candidates": [{"family": c["family"], "terms": {u.label(): float(c["values"][u]) for u in c["terms"]},
                               "heldout_cost": c["heldout_cost"], "z": c.get("z")} for c in tied]}
        say(f"class test: {fam} at {joint or 'all joints'}: "
            + ("; ".join(f"{c['family']} cost {c['heldout_cost']:.1f}" for c in cands))
            + (f" -> {w['family']} named" if status == "found"
               else f" -> cannot tell {', '.join(c['family'] for c in tied)} apart ({seg} would)"))
        if win != 0 and depth < 1 and rival_families(w["family"]):
            # the winner of another class has rivals of its own (a kp error that beat a centre of mass,
            # against a torque-constant error): it is tested in turn, its decision replaces this one
            queue.insert(0, (w["family"], list(w.get("own", w["terms"])), depth + 1))
            continue
        out.decisions.append(dec)
    return out


def _winner(cands: list[dict], costs: Sequence[float], gap: float) -> int:
    """Index of the class test's winner among ``cands`` (the tested effect first; dicts with ``at_bound``
    and optionally ``nests``) whose held-out costs are ``costs``: the lowest cost, but a candidate fitted
    at a bound of its family (a distorted form) only if no other comes within ``gap`` of it, and a
    candidate that nests the tested effect (``nests``: a Stribeck friction over its Coulomb level) only
    if it beats the tested effect by ``gap`` (parsimony: the richer form must earn its parameters)."""
    win = int(np.argmin(costs))
    valid = [i for i, c in enumerate(cands) if not c["at_bound"]]
    if valid:
        best_valid = min(valid, key=lambda i: costs[i])
        if costs[best_valid] - costs[win] < gap:
            win = best_valid
    if cands[win].get("nests") and not cands[0]["at_bound"] and costs[0] - costs[win] < gap:
        win = 0
    return win


#: Families of a joint's velocity-proportional torque, refitted beside a Stribeck rival in the class test.
DAMPING_FAMILIES = ("viscous_damping", "kd_gain")
#: Second start [rad/s] of a Stribeck velocity fitted in the class test (the first is the library's
#: :data:`sysid.model.STRIBECK_VELOCITY`): friction whose static excess fades over several tenths of a
#: rad/s (BAM's servos, Duclusaud et al., arXiv:2410.08650) is far from the default's basin.
SLOW_STRIBECK_START = 0.4


#: A rival family is fitted in the class test only if its linearised probes explain at least this share
#: of what the tested effect explains on the training logs (:func:`_plausible_rivals`).
RIVAL_SHARE = 0.3


def _plausible_rivals(problem: Problem, model: dict, rest: dict, rival_sets: dict, robot) -> list[str]:
    """The rival families worth a nonlinear fit: what the tested effect explains is the training
    residual energy of ``rest`` (the model without it) minus that of ``model``; each rival's probe
    columns around ``rest`` (its probe, and its large probe or its mirror) are fitted to the residual of
    ``rest`` by least squares (non-negative weights for one-sided families), and the rival is kept
    when that explains at least :data:`RIVAL_SHARE` of it (one batched replay of every probe)."""
    if not rival_sets:
        return []
    sets, owners = [rest, model], []
    for g, rts in rival_sets.items():
        fam = FAMILIES[g]
        sets.append({**rest, **{u: float(term_probe(u, robot)) for u in rts}})
        owners.append((g, 1.0))
        if fam.probe2 is not None:
            sets.append({**rest, **{u: float(fam.probe2) for u in rts}})
            owners.append((g, 1.0))
    R = problem.residuals(problem.predict(sets, "train"), "train")
    r0 = R[0]
    e_rest, e_model = float(r0 @ r0), float(R[1] @ R[1])
    need = e_rest - e_model
    out = []
    for g in rival_sets:
        cols = np.stack([r0 - R[2 + i] for i, (o, _) in enumerate(owners) if o == g], axis=1)
        if two_sided(g):
            w, *_ = np.linalg.lstsq(cols, r0, rcond=None)
        else:
            w, _ = nnls(cols, r0, maxiter=50 * cols.shape[1])
        left = r0 - cols @ w
        if e_rest - float(left @ left) >= RIVAL_SHARE * need:
            out.append(g)
    return out


def _at_bound(t: Term, v: float, robot) -> bool:
    """Whether value ``v`` of term ``t`` is within :data:`BOUND_TOL` of its family's range from a bound."""
    lo, hi = term_bounds(t, robot)
    tol = BOUND_TOL * (hi - lo)
    return v - lo <= tol or hi - v <= tol


def _split_classes(found: list[dict], decisions: list[dict], robot) -> tuple[list[dict], list[dict]]:
    """Found entries whose effect the class test could not separate from a rival leave ``found`` for the
    returned equivalence entries: {``class``, ``words``, ``where``, ``joints``, ``links``,
    ``family`` (the best-fitting candidate, kept in the model), ``candidates`` ([{family, words,
    terms, display, heldout_cost, z}]), ``segment``, ``experiment``, ``heldout_cost_without``}.
    A found entry whose decision lists a nested excess it could not exclude gains ``not_excluded``
    (the decision's list). Returns (found, equivalent), new lists."""
    from sysid.equivalence import CLASSES

    found = list(found)
    equivalent = []
    for d in decisions:
        if d["status"] != "class":
            if d.get("not_excluded"):
                labels = {t.label() for t in d["terms"]}
                found = [{**e, "not_excluded": d["not_excluded"]} if e.get("term_label") in labels else e
                         for e in found]
            continue
        labels = {t.label() for t in d["terms"]}
        mine = [e for e in found if e.get("term_label") in labels]
        if not mine:
            continue
        found = [e for e in found if e not in mine]
        fams = [c["family"] for c in d["candidates"]]
        cls = next((c.name for c in CLASSES.values() if all(f in c.families for f in fams)), None)
        cands = []
        for c in d["candidates"]:
            fam = FAMILIES[c["family"]]
            disp = ", ".join(f"{lbl} {fam.fmt(v)}" for lbl, v in c["terms"].items())
            cands.append({"family": c["family"], "words": fam.words, "terms": c["terms"], "display": disp,
                          "heldout_cost": c["heldout_cost"], "z": c["z"]})
        e0 = mine[0]
        equivalent.append({"class": cls, "words": d["words"], "where": e0["where"], "joints": e0["joints"],
                           "links": e0["links"], "family": d["family"], "candidates": cands,
                           "segment": d["segment"], "experiment": d["experiment"],
                           "heldout_cost_without": float(sum(e["heldout_cost_without"] for e in mine)),
                           "value": e0["value"], "ci95": e0["ci95"], "unit": e0["unit"], "display": e0["display"]})
    return found, equivalent


def _check_roughness(rough: RoughnessFit | None, problem: Problem, model: dict,
                     say: Callable[[str], None]) -> list[dict]:
    """Withdraw a declared roughness the deterministic model explains: if what ``model`` leaves
    corresponds to less than the smallest reported RMS height (or held-out excess), ``rough`` is
    updated in place (``declared`` False, ``reason``; ``excess_heldout_left`` always set) and its
    rejection record returned."""
    rejected = []
    if rough is not None and rough.declared and model:
        from sysid.roughness import MIN_HELDOUT_EXCESS, MIN_RMS_HEIGHT, excess_left

        left, ho_left = excess_left(rough, problem, model)
        rough.excess_heldout_left = ho_left
        if left < MIN_RMS_HEIGHT or ho_left < MIN_HELDOUT_EXCESS:
            rough.declared = False
            rough.reason = (f"the deterministic model ({', '.join(t.label() for t in model)}) explains the excess "
                            f"over flat ground: what it leaves corresponds to {1000 * left:.2f} mm RMS (held-out "
                            f"excess {ho_left:.2f} floor²), below the smallest reported ({1000 * MIN_RMS_HEIGHT:.1f} mm)")
            say(f"terrain roughness: rejected: {rough.reason}")
            rejected.append({"term": "terrain_roughness", "family": "terrain_roughness", "value": rough.rms_height,
                             "reason": rough.reason})
    return rejected


def _roughness_effect(rough: RoughnessFit | None, model: dict, effects: list[dict],
                      indist: list[dict]) -> tuple[list[dict], list[dict]]:
    """A declared roughness as an effect (RMS height [m], stochastic), effects re-sorted by held-out
    need, and each contact term of ``model`` marked indistinguishable from it.

    Returns:
        (effects, indistinguishable), new lists.
    """
    effects, indist = list(effects), list(indist)
    if rough is not None and rough.declared:
        fam = FAMILIES["terrain_roughness"]
        effects.append({"family": "terrain_roughness", "joints": [], "links": [], "value": rough.rms_height,
                        "unit": "m", "ci95": [rough.ci95[0], rough.ci95[1]], "nominal": 0.0, "words": fam.words,
                        "where": "feet/ground (stance)",
                        "display": (f"{1000 * rough.rms_height:.2f} mm RMS height (the model's surfaces peak at "
                                    f"{1000 * rough.peak_height:.1f} mm; {100 * CORRELATION_RADIUS:.0f} cm correlation "
                                    "radius assumed)"),
                        # what the deterministic model leaves on held-out logs, as far as such ground explains it
                        "heldout_cost_without": min(rough.excess_heldout_obs if rough.excess_heldout_left is None
                                                    else rough.excess_heldout_left, rough.excess_heldout_pred),
                        "stochastic": True,
                        "evidence": rough.reason})
        effects.sort(key=lambda e: -e["heldout_cost_without"])
        for t in model:
            if t.fam.contact:
                indist.append({"a": t.label(), "b": "terrain_roughness", "corr": float("nan"),
                               "experiment": "the same stepping logs on a flat, hard floor: a contact parameter "
                                             "stays, the signature of uneven ground goes"})
    return effects, indist


def _after(logs: list[Log], problem: Problem, setup: _Setup, base: _Baseline, before: _Before,
           model: dict) -> _After:
    """The residual the final model leaves: held-out RMS and energy, share of the gap closed, and a
    localisation of all windows replayed under base model + ``model`` (whiteness, phases,
    joints still above FLAG_ENERGY floor²)."""
    rms_after, per_after = problem.rms(model, "heldout")
    e_after = problem.channel_energy(problem.predict([model], "heldout"), "heldout")[0]
    gap_closed = None
    fl2 = base.floor_sq
    if before.rms ** 2 > fl2 * 1.0001:
        gap_closed = float((before.rms ** 2 - rms_after ** 2) / (before.rms ** 2 - fl2))
    # residual after the fit: per joint, whiteness, phases
    preds_all = predict(logs, setup.all_windows, [{**setup.base_model, **model}], with_imu=setup.with_imu)
    loc_after = localisation(logs, setup.all_windows, [p[0] for p in preds_all], base.floor, base.names)
    unexplained = [nm for nm in base.names[:problem.n_joints]
                   if loc_after["channels"][nm]["rms_over_floor"] ** 2 > FLAG_ENERGY]
    return _After(rms=rms_after, per_joint=per_after, energy=e_after, gap_closed=gap_closed, localisation=loc_after,
                  unexplained=unexplained)


def class_sentence(e: dict) -> str:
    """One equivalence entry (:func:`_split_classes`) in words: the class at its place, its
    candidates, and the excitation segment that would tell them apart."""
    cands = " or ".join(f"{c['words']} ({c['display']})" for c in e["candidates"])
    return (f"{e['words'] or 'effect'} at {e['where']}: {cands}; these logs cannot tell them apart "
            f"(record the {e['segment']} segment, {e['experiment']}: sgatwalk excite --segments +{e['segment']}, "
            "and diagnose again)")


def _verdict(before: _Before, after: _After, effects: list[dict], uncertain: list[dict], base: _Baseline,
             rough: RoughnessFit | None, calibration: dict | None, source: str, *,
             roughness_skipped: bool = False, equivalent: list[dict] = ()) -> _Verdict:
    """The one-paragraph verdict (nothing to explain / nothing explains it / what was found, and the
    effects named only as a class: ``equivalent``, :func:`_split_classes`), the
    roughness note, the caution for noise-free recordings without an engine-gap calibration, the
    caution that the time budget ran out before uneven ground was tested (``roughness_skipped``), and
    a warning (not in the verdict) when the calibration replayed its base state differently
    (``source``: this diagnosis's :func:`sysid.data.base_state_source`)."""
    noise_floor = base.noise_floor
    rms_before, rms_after = before.rms, after.rms
    words = "; ".join(f"{e['words']} {e['display']} at {e['where']}" + "".join(
        f" ({FAMILIES[n['family']].words} of {', '.join(f'{v:.3g}' for v in n['terms'].values())} "
        f"{FAMILIES[n['family']].unit} not excluded: the {n['segment']} segment would show it)"
        for n in e.get("not_excluded", ())) for e in effects)
    if before.nothing and not effects:
        verdict = (f"no missing physics: held-out RMS {1000 * rms_before:.2f} mrad is at the noise floor "
                   f"({1000 * noise_floor:.2f} mrad); no joint's residual energy exceeds 1.5x its floor's")
    elif before.nothing:  # only the weighing found something: replayed with it, nothing is left to explain
        verdict = (f"Found: {words}. Replayed with it, held-out RMS {1000 * rms_before:.2f} mrad is at the noise "
                   f"floor ({1000 * noise_floor:.2f} mrad); no joint's residual energy exceeds 1.5x its floor's")
    elif not effects and not equivalent and uncertain:
        verdict = (f"held-out RMS {1000 * rms_before:.2f} -> {1000 * rms_after:.2f} mrad (noise floor "
                   f"{1000 * noise_floor:.2f} mrad) with {len(uncertain)} fitted term(s), but none passes the tests "
                   f"for a finding (uncertain: {'; '.join(e['words'] + ' at ' + e['where'] for e in uncertain)})")
    elif not effects and not equivalent and not flagged_joints(before.energy_heldout, base.names):
        # the effect shows in the training logs only: the held-out logs cannot test any candidate
        worst = flagged_joints(before.energy_train, base.names)[:3]
        verdict = (f"cannot tell: the residual stands above the noise at {', '.join(worst) or '-'} in the training "
                   f"logs only; the held-out logs leave it at the noise floor (held-out RMS {1000 * rms_before:.2f} "
                   f"mrad vs {1000 * noise_floor:.2f} mrad), so no candidate can be confirmed there (record more "
                   "logs that move those joints, e.g. sgatwalk excite --logs 6, and diagnose again)")
    elif not effects and not equivalent:
        worst = flagged_joints(before.energy_heldout, base.names)[:3]
        verdict = (f"no candidate effect explains the residual: held-out RMS {1000 * rms_before:.2f} mrad vs noise "
                   f"floor {1000 * noise_floor:.2f} mrad, largest at {', '.join(worst)} (an effect outside the "
                   "library, or an engine gap larger than calibrated)")
    else:
        verdict = (f"held-out RMS {1000 * rms_before:.2f} -> {1000 * rms_after:.2f} mrad (noise floor "
                   f"{1000 * noise_floor:.2f} mrad), {100 * (after.gap_closed or 0):.0f} % of the gap closed. "
                   + (f"Found: {words}" if effects else "Found: nothing named beyond its class"))
        if equivalent:
            verdict += ". Named as a class only: " + "; ".join(class_sentence(e) for e in equivalent)
        if uncertain:
            verdict += (f". Uncertain or compensating (kept in the model, not claimed): "
                        f"{'; '.join(e['words'] + ' at ' + e['where'] for e in uncertain)}")
        if after.unexplained:
            verdict += f". Still above 1.5x floor energy: {', '.join(after.unexplained)}"
    if rough is not None and rough.declared:
        verdict += (f". The residual left is what uneven ground of {1000 * rough.rms_height:.2f} mm RMS height gives "
                    f"(held-out excess {rough.excess_heldout_obs:.1f} floor², simulated logs on such ground "
                    f"{rough.sim_log_excess[0]:.1f}-{rough.sim_log_excess[2]:.1f}); a random surface is not the one "
                    "that was there, so it does not lower the RMS")
    warnings = []
    if calibration is None and base.sigma["encoders"] < NOISE_FREE_SIGMA and not before.nothing:
        # noise-free recordings (a simulator) judged against their own numerical noise: an engine gap
        # between the recording simulator and this sim is hundreds of floors and is read as physics
        warnings.append(f"the recordings' encoder noise is {1000 * base.sigma['encoders']:.3f} mrad and no engine-gap "
                        "calibration was given: every difference between the recording's simulator (or robot) and "
                        "this sim counts as missing physics; record logs without injected effects, run "
                        "'sgatwalk diagnose --calibrate' on them and pass --calibration")
        verdict += ". CAUTION: " + warnings[-1]
    if roughness_skipped:
        # more logs take longer to screen: a budget that suits three stepping logs may end before the
        # roughness stage on nine, and the ground the robot walks on would silently go unmodelled
        warnings.append("the time budget ran out before the uneven-ground stage: terrain roughness was not tested "
                        "(raise --time-budget)")
        verdict += ". CAUTION: " + warnings[-1]
    cal_source = (calibration or {}).get("base_state")
    if cal_source and cal_source != source:
        warnings.append(f"base state: the calibration's replays used {cal_source.split(' (')[0]}, this diagnosis's "
                        f"{source.split(' (')[0]}: its engine gap is not the gap of these replays; calibrate the "
                        "same way (both with or both without --use-ground-truth)")
    return _Verdict(text=verdict, warnings=warnings)


def _report(logs: list[Log], setup: _Setup, base: _Baseline, loc: dict, problem: Problem, before: _Before,
            sel: _Selection, iv: _Intervals, effects: list[dict], uncertain: list[dict], indist: list[dict],
            rejected: list[dict],
            rough: _RoughnessStage, after: _After, verdict: _Verdict, calibration: dict | None, robot,
            clock: _Clock, source: str) -> dict:
    """The report dict (key order as written to ``report.json``), plus the private ``_base_terms``
    and ``_model_terms`` (Term -> value, for the MJCF export and plots; not in the JSON)."""
    names, model, rough_fit = base.names, iv.model, rough.fit
    considered = sorted({lbl.split("[")[0].replace("(-)", "") for lbl in sel.screened})
    if rough_fit is not None:
        considered = sorted(set(considered) | {"terrain_roughness"})
    report = {
        "verdict": verdict.text,
        "warnings": verdict.warnings,
        "noise_floor": base.noise_floor,
        "heldout_rms_before": before.rms,
        "heldout_rms_after": after.rms,
        "gap_closed": after.gap_closed,
        "effects": effects,
        "uncertain": uncertain,
        "rejected": rejected,
        "families_considered": list(setup.families),
        "families_screened": considered,
        "indistinguishable": indist,
        "rounds": sel.rounds,
        "residual": {
            "per_joint_rms_before": {nm: float(v) for nm, v in zip(robot.joint_names, before.per_joint)},
            "per_joint_rms_after": {nm: float(v) for nm, v in zip(robot.joint_names, after.per_joint)},
            "per_joint_rms_over_floor_after": {nm: after.localisation["channels"][nm]["rms_over_floor"]
                                               for nm in names},
            "whiteness_after": {nm: after.localisation["channels"][nm]["whiteness"]
                                for nm in names[:len(robot.joint_names)]},
            "phases_after": after.localisation["phases"],
            "groups_after": after.localisation["groups"],
            "heldout_energy_after": {nm: float(v) for nm, v in zip(names, after.energy)},
            "unexplained_joints": after.unexplained,
        },
        "localisation": loc,
        "noise": {"sigma": base.sigma, "sigma_source": "the diagnosed logs (nominal replay residual)",
                  "calibration_sigma": (calibration or {}).get("sigma"),
                  "floor_per_channel": {nm: float(v) for nm, v in zip(names, base.floor)},
                  "engine_gap_calibrated": calibration is not None},
        "base_state": source,
        "split": {"train": [logs[i].name for i in setup.train_idx], "heldout": [logs[i].name for i in setup.heldout_idx],
                  "note": setup.split_note,
                  "mode": "single shooting" if setup.fixed else f"windowed replay ({WINDOW_S} s)"},
        "heldout_cost_before": before.c0, "heldout_cost_after": iv.cost, "channels": problem.k,
        "model": {t.label(): float(v) for t, v in model.items()},
        "base_model": {t.label(): float(v) for t, v in setup.base_model.items()},
        "runtime_s": clock.elapsed(),
        "time_budget_reached": sel.budget_hit or rough.budget_hit,
        "rollouts": problem.n_rollouts,
        "fixed_base": setup.fixed,
        "terrain_roughness": None if rough_fit is None else dataclasses.asdict(rough_fit),
    }
    report["_base_terms"] = setup.base_model
    report["_model_terms"] = {**setup.base_model, **model}  # for the MJCF export and plots; not in the JSON
    return report
