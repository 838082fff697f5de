"""Each physical form of the library's effects: injected (synthetic short logs made with the candidate
augmentations, 1 mrad noise), screened with the default library and refitted to its value.

The forms beside the families of ``tests/test_sysid_families.py``: a servo's kd alone and kp and kd
together (screened as one (kp, kd) subspace per joint), backlash on either side of the encoder, a
torque limit on one joint and a back-EMF torque-speed limit, Stribeck friction, a link's centre of
mass and rotational inertia, an encoder offset the servo sees, a low-pass on the commands; and the
candidate models' own properties (a form at its nominal value is the plain sim, the joint block's
partners join a pick)."""

import copy

import numpy as np
import pytest

from robots import nao_h25
from sysid.candidates import FIXED_BASE_FAMILIES, Term, apply_terms, readout, series_structure
from sysid.identify import Problem, refit, screen
from sysid.model import Structure, replay_model
from sysid.replay import predict, whole_logs
from sysid.synthetic import synthetic_logs

SEGMENTS = ("holds", "ramps", "steps", "reversals", "chirp")

CASES = [
    ({Term("kd_gain", "LHipRoll"): 0.4}, 0.05),
    ({Term("backlash_motor", "RKneePitch"): 0.03}, 0.15),
    ({Term("backlash_link", "RKneePitch"): 0.03}, 0.15),
    ({Term("joint_torque_limit", "LHipPitch"): 0.5}, 0.05),
    ({Term("back_emf", "LKneePitch"): 1.0}, 0.05),
    ({Term("stribeck_friction", "LHipPitch"): 0.15}, 0.15),
    ({Term("link_com", "LTibia:x"): 0.02}, 0.10),
    ({Term("command_lowpass"): 0.015}, 0.05),
]


def _problem(truth, segments=SEGMENTS, seconds=3.0):
    logs = synthetic_logs(truth, n_logs=2, seconds=seconds, seed=3, traj_seed=40, segments=segments)
    return Problem(logs, whole_logs(logs, [0]), whole_logs(logs, [1]), np.full(24, 1e-3))


@pytest.mark.slow
@pytest.mark.parametrize("truth,tol", CASES, ids=[next(iter(c[0])).family for c in CASES])
def test_form_injected_screened_and_recovered(truth, tol):
    robot = nao_h25()
    problem = _problem(truth)
    (t_true, v_true), = truth.items()
    sr = screen(problem, robot, {}, FIXED_BASE_FAMILIES)
    assert t_true in sr.selected, f"screening picked {[t.label() for t in sr.selected]}"
    fit = refit(problem, {t_true: sr.selected[t_true]})  # the pick alone (the diagnosis prunes the others)
    err = abs(fit.values[t_true] - v_true) / abs(v_true - t_true.fam.nominal)
    assert err < tol, f"{t_true.label()}: fitted {fit.values[t_true]:.5g}, truth {v_true:.5g}"
    c = problem.cost([{}, fit.values], "heldout")
    assert c[1] - 24 < 0.3 * (c[0] - 24)


@pytest.mark.slow
def test_kp_and_kd_together_are_named_a_torque_constant_error():
    """The strangers' world's servo error: kp and kd x0.7 at an elbow was named a series compliance before.
    Screened as one (kp, kd) subspace per joint, refitted together, named by the form step and tested
    against its class (a centre of mass that screening may pick first loses to the servo, which is
    tested against its own class in turn), the diagnosis names the torque-constant error."""
    from sysid.diagnose import diagnose

    truth = {Term("torque_constant", "LElbowRoll"): 0.7}
    logs = synthetic_logs(truth, n_logs=3, seconds=4.0, seed=3, traj_seed=40, segments=SEGMENTS)
    rep = diagnose(logs)
    named = [e for e in rep["effects"] if e["family"] == "torque_constant" and e["joints"] == ["LElbowRoll"]]
    assert named, rep["verdict"]
    assert abs(named[0]["value"] - 0.7) < 0.03


def test_the_servo_form_step_names_kp_and_kd_together():
    """A (kp, kd) pair fitted to kp and kd x0.7 is one torque-constant error (fitted through mujoco.sysid)."""
    from sysid.diagnose import servo_forms

    problem = _problem({Term("torque_constant", "LElbowRoll"): 0.7})
    model, merged = servo_forms(problem, {Term("pd_gain", "LElbowRoll"): 0.702, Term("kd_gain", "LElbowRoll"): 0.698})
    assert Term("torque_constant", "LElbowRoll") in model and merged
    assert abs(model[Term("torque_constant", "LElbowRoll")] - 0.7) < 0.01


@pytest.mark.parametrize("family,target", [("backlash", "LKneePitch"), ("backlash_motor", "LKneePitch"), ("backlash_link", "LKneePitch"),
                                           ("stribeck_friction", "LHipPitch"), ("kd_gain", "LHipRoll"),
                                           ("joint_torque_limit", "LHipPitch"), ("back_emf", "LKneePitch"),
                                           ("link_com", "LTibia:y"), ("link_inertia", "LThigh"),
                                           ("encoder_offset", "LHipPitch"), ("command_lowpass", None)])
def test_a_form_at_its_nominal_value_is_the_plain_sim(family, target):
    """A candidate must reduce to the nominal model at its zero value (else zero-valued terms survive
    pruning): replays at nominal agree with the plain sim's within 0.1 mrad; a series play hinge (closed
    to 0.2 mrad, coupled through a stiff limit) within the 1 mrad noise floor in RMS, as ``backlash``'s."""
    t = Term(family, target)
    logs = synthetic_logs({}, n_logs=1, seconds=3.0, noise=0.0, traj_seed=5, segments=("holds", "chirp"))
    y0, y1 = predict(logs, whole_logs(logs), [{}, {t: t.fam.nominal}])[0]
    if family.startswith("backlash"):
        assert np.sqrt(np.mean((y1 - y0) ** 2)) < 1e-3
    else:
        assert np.max(np.abs(y1 - y0)) < 1e-4


def test_servo_terms_compose_and_a_torque_constant_scales_the_ceiling():
    robot = nao_h25()
    j = "LKneePitch"
    i = robot.joint_names.index(j)
    vals = {Term("pd_gain", j): 0.8, Term("kd_gain", j): 0.5, Term("torque_constant", j): 0.9,
            Term("torque_limit"): 0.8, Term("back_emf", j): 0.2}
    rm = replay_model(series_structure(Structure(), vals))
    m = copy.copy(rm.model)
    apply_terms(rm, m, vals)
    a = rm.act[i]
    assert m.actuator_gainprm[a, 0] == pytest.approx(robot.kp[i] * 0.8 * 0.9)
    assert m.actuator_biasprm[a, 1] == pytest.approx(-robot.kp[i] * 0.8 * 0.9)
    # kd inside the clip lowered by the back-EMF slope, which acts outside it on the joint's damping
    assert m.actuator_biasprm[a, 2] == pytest.approx(-robot.kd[i] * 0.5 * 0.9 + 0.2)
    assert m.dof_damping[rm.dadr[i]] == pytest.approx(rm.model.dof_damping[rm.dadr[i]] + 0.2)
    assert m.actuator_forcerange[a, 1] == pytest.approx(robot.effort[i] * 0.8 * 0.9)


def test_the_backlash_forms_split_the_servo_damping_and_the_encoder_reads_the_motor_behind_link_side_play():
    robot = nao_h25()
    j = "RKneePitch"
    i = robot.joint_names.index(j)
    for fam, motor_share, reads_play in (("backlash", 0.1, True), ("backlash_motor", 1.0, True),
                                         ("backlash_link", 1.0, False)):
        vals = {Term(fam, j): 0.02}
        rm = replay_model(series_structure(Structure(), vals))
        m = copy.copy(rm.model)
        apply_terms(rm, m, vals)
        assert m.dof_damping[rm.dadr[i]] == pytest.approx(motor_share * robot.kd[i])
        assert m.tendon_damping[rm.play_tendon[j]] == pytest.approx((1 - motor_share) * robot.kd[i])
        meas, servo = readout(rm, vals)
        play_col = rm.model.sensor_adr[rm.model.sensor(f"play:{j}").id]
        assert (meas[i, play_col] == 1.0) == reads_play and not servo.any()
    with pytest.raises(ValueError, match="exclude each other"):
        vals = {Term("backlash", j): 0.02, Term("backlash_motor", j): 0.02}
        rm = replay_model(series_structure(Structure(), vals))
        apply_terms(rm, copy.copy(rm.model), vals)


def test_an_encoder_offset_shifts_the_servo_and_a_readout_offset_only_the_log():
    """The servo of a joint with an encoder offset b drives the link to q* - b, the log reads about q*;
    an offset of the logged angle alone leaves the link at q* and the log reads q* + b."""
    j = "HeadYaw"  # no gravity load about a vertical axis
    i = nao_h25().joint_names.index(j)
    logs = synthetic_logs({}, n_logs=1, seconds=3.0, noise=0.0, traj_seed=5, segments=("holds",))
    y0, ye, yr = predict(logs, whole_logs(logs), [{}, {Term("encoder_offset", j): 0.01},
                                                  {Term("sensor_bias", j): 0.01}])[0]
    assert np.max(np.abs(ye[:, i] - y0[:, i])) < 1e-4
    assert np.allclose(yr[50:, i] - y0[50:, i], 0.01, atol=1e-4)  # after the start (logged without the offset)


def test_the_joint_blocks_partner_joins_a_pick_at_its_nominal_value():
    """Screening picks kp at a joint; kd of the same servo joins it (at x1), so the refit moves both."""
    robot = nao_h25()
    problem = _problem({Term("pd_gain", "LAnklePitch"): 0.6}, seconds=3.0)
    sr = screen(problem, robot, {}, ("pd_gain", "kd_gain", "latency"))
    assert Term("pd_gain", "LAnklePitch") in sr.selected
    assert sr.selected.get(Term("kd_gain", "LAnklePitch")) == 1.0


def test_the_servo_blocks_torque_constant_direction_scales_kp_and_kd_by_one_factor():
    """The servo block's diagonal for stage B moves kp and kd each by its own probe (x0.85, x0.6); the
    one that ranks the block in stage A (``one_factor``) is the torque-constant direction: kp and kd both
    x0.85 (and the mirror, both x1.15). Only for the block's first family, with its partner considered."""
    from sysid.identify import _block_diagonals

    robot = nao_h25()
    fams, joints, label = ("pd_gain", "kd_gain", "latency"), ["LAnklePitch", "RKneePitch"], "pd_gain[LAnklePitch+RKneePitch]"
    own = _block_diagonals(robot, "pd_gain", fams, {}, joints, label)
    one = _block_diagonals(robot, "pd_gain", fams, {}, joints, label, one_factor=True)
    assert [c.label for c in one] == ["pd_gain+kd_gain[LAnklePitch+RKneePitch]",
                                      "pd_gain+kd_gain[LAnklePitch+RKneePitch](-)"]
    terms = {Term(f, j) for f in ("pd_gain", "kd_gain") for j in joints}
    for col, v in zip(one, (0.85, 1.15)):
        assert set(col.terms) == terms and all(x == pytest.approx(v) for x in col.terms.values()), col.terms
    assert {t.family: v for t, v in own[0].terms.items()} == {"pd_gain": pytest.approx(0.85), "kd_gain": pytest.approx(0.6)}
    assert _block_diagonals(robot, "kd_gain", fams, {}, joints, "kd_gain[LAnklePitch]", one_factor=True) == []
    assert _block_diagonals(robot, "pd_gain", ("pd_gain",), {}, joints, label, one_factor=True) == []


def test_a_torque_constant_error_at_an_ankle_reaches_stage_b_as_the_servo_block():
    """kp and kd x0.72 at LAnklePitch (the strangers' servo error): screened on the default fixed-base
    families, the servo block (kp and kd at that joint) is selected, not a gear play or a series spring
    in its place, because stage A ranks the block by its torque-constant direction as well."""
    logs = synthetic_logs({Term("torque_constant", "LAnklePitch"): 0.72}, n_logs=3, seconds=3.0, seed=3, traj_seed=40)
    problem = Problem(logs, whole_logs(logs, [0, 1]), whole_logs(logs, [2]), np.full(24, 1e-3))
    sr = screen(problem, nao_h25(), {}, FIXED_BASE_FAMILIES)
    assert {t.label() for t in sr.selected} == {"pd_gain[LAnklePitch]", "kd_gain[LAnklePitch]"}


@pytest.mark.slow
def test_a_stribeck_friction_is_fitted_with_its_stribeck_velocity():
    """BAM's M2 form: the static excess falls away over a fitted Stribeck velocity. Logs of moves at
    several constant speeds with friction whose excess fades over 0.4 rad/s are fitted better with the
    velocity free than at the library's default (0.1 rad/s), and the velocity comes back; the class test of the Coulomb friction
    that screening finds fits its Stribeck rival with the velocity too."""
    import time

    from sysid.diagnose import _Clock, _equivalence
    from sysid.model import STRIBECK_VELOCITY

    robot = nao_h25()
    j = "LHipPitch"
    cf, sf, sv = Term("coulomb_friction", j), Term("stribeck_friction", j), Term("stribeck_velocity", j)
    problem = _problem({cf: 0.1, sf: 0.15, sv: 0.4}, segments=("holds", "velocity_sweep", "reversals"), seconds=4.0)
    fixed = refit(problem, {cf: 0.1, sf: 0.1})
    free = min((refit(problem, {cf: 0.1, sf: 0.1, sv: v0}) for v0 in (STRIBECK_VELOCITY, 0.4)), key=lambda f: f.cost)
    # a shape difference, not a level one: the sum of squared residuals (over ~9600 of noise) drops by > 5
    assert free.cost < fixed.cost - 5
    assert 0.25 < free.values[sv] < 0.65, free.values[sv]
    coulomb = refit(problem, {cf: 0.15})
    cost = float(problem.cost([coulomb.values], "heldout")[0])
    eq = _equivalence(problem, coulomb.values, cost, robot, _Clock(time.perf_counter(), None), lambda s: None)
    assert any("stribeck_friction" in (t["winner"], t["rival"]) for t in eq.tests)
    if sf in eq.model:  # the Stribeck form won: its velocity came with it
        assert 0.2 < eq.model[sv] < 0.8
