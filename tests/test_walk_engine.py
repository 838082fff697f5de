"""WalkEngine without physics: outputs, determinism, feedback signs, purity, diagnostics, speed."""

import subprocess
import sys

import numpy as np
import pytest

from robots import nao_h25
from robots.observation import ObservationLayout
from walk_engine import STAND, GaitParams, WalkCommand, WalkEngine

ROBOT = nao_h25()
SL = {**ObservationLayout(ROBOT).slices, "size": ObservationLayout(ROBOT).size}


def _obs(q=None, gyro=(0.0, 0.0, 0.0), fsr=(20.0, 20.0), angle=(0.0, GaitParams().torso_pitch)):
    o = np.zeros(SL["size"])
    o[SL["q"]] = ROBOT.pose("crouch") if q is None else q
    o[SL["gyro"]] = gyro
    o[SL["angle"]] = angle
    o[SL["fsr"]] = fsr
    return o


def test_observation_layout_matches_envs():
    from envs import ObservationLayout

    lay = ObservationLayout(ROBOT)
    assert SL["size"] == lay.size
    for k, s in lay.slices.items():
        assert SL[k] == s


def test_walk_engine_imports_no_physics_engine():
    code = ("import sys, walk_engine, walk_engine.engine; "
            "bad = [m for m in ('mujoco', 'pybullet', 'envs', 'torch') if m in sys.modules]; "
            "assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=str(__import__("pathlib").Path(__file__).parents[1]))


def test_targets_shape_limits_and_blend_from_measured_pose():
    eng = WalkEngine(ROBOT)
    q0 = ROBOT.pose("crouch")
    eng.reset(_obs(q0), info={"base_pos": "never read"})
    a = eng.step(_obs(q0))
    assert a.shape == (23,) and np.all(np.isfinite(a))
    lo, hi = ROBOT.lower[ROBOT.actuated_index], ROBOT.upper[ROBOT.actuated_index]
    # the first target is a small step from the measured pose (blend over BLEND_TIME)
    assert np.abs(a - q0[ROBOT.actuated_index]).max() < 0.01
    rng = np.random.default_rng(0)
    for _ in range(800):
        a = eng.step(_obs(gyro=rng.normal(0, 2.0, 3)))
        assert np.all(np.isfinite(a)) and np.all(a >= lo) and np.all(a <= hi)


def test_deterministic_and_reset_restarts():
    rng = np.random.default_rng(1)
    obs = [_obs(gyro=rng.normal(0, 0.5, 3)) for _ in range(400)]
    e1, e2 = WalkEngine(ROBOT), WalkEngine(ROBOT)
    for e in (e1, e2):
        e.reset(obs[0])
    out1 = np.array([e1.step(o) for o in obs])
    out2 = np.array([e2.step(o) for o in obs])
    assert np.array_equal(out1, out2)
    e1.reset(obs[0])
    assert np.array_equal(np.array([e1.step(o) for o in obs]), out1)


def test_feedback_signs_on_support_leg():
    """Forward pitch (rate or angle) -> support ankle pitch up (push the toes down); rightward
    roll (+x) -> support ankle and hip roll up (tilt the body back to the left)."""
    act = ROBOT.actuated_joint_names
    p = GaitParams(gyro_ankle_pitch_gain=0.1, gyro_ankle_roll_gain=0.1, gyro_hip_roll_gain=0.1)
    engines = [WalkEngine(ROBOT, p, torso_angle_gain=0.5) for _ in range(4)]
    for e in engines:
        e.reset()
    tilted = _obs(angle=(0.1, p.torso_pitch + 0.1))
    inputs = [_obs(), _obs(gyro=(0.0, 0.5, 0.0)), _obs(gyro=(0.5, 0.0, 0.0)), tilted]
    for _ in range(60):  # into the first single support (left foot supports)
        a0, a1, a2, a3 = (e.step(o) for e, o in zip(engines, inputs))
    base = engines[0]
    assert base.phases[base._ph_i].kind == "ss" and base.phases[base._ph_i].support == "L"
    i = {n: act.index(n) for n in ("LAnklePitch", "LAnkleRoll", "LHipRoll", "RAnklePitch", "RAnkleRoll")}
    assert a1[i["LAnklePitch"]] - a0[i["LAnklePitch"]] > 0.03
    assert a1[i["RAnklePitch"]] == pytest.approx(a0[i["RAnklePitch"]], abs=1e-9)  # swing leg untouched
    assert a2[i["LAnkleRoll"]] - a0[i["LAnkleRoll"]] > 0.03
    assert a2[i["LHipRoll"]] - a0[i["LHipRoll"]] > 0.03
    assert a3[i["LAnklePitch"]] - a0[i["LAnklePitch"]] == pytest.approx(0.05, abs=1e-9)
    assert a3[i["LAnkleRoll"]] - a0[i["LAnkleRoll"]] == pytest.approx(0.05, abs=1e-9)
    assert a3[i["RAnkleRoll"]] == pytest.approx(a0[i["RAnkleRoll"]], abs=1e-9)


def test_standing_command_keeps_feet_in_place_and_stop_ends_standing():
    eng = WalkEngine(ROBOT, command=STAND)
    eng.reset()
    for _ in range(300):
        eng.step(_obs())
    d = eng.diagnostics()
    assert np.ptp(d["foot_L_x"]) < 1e-12 and np.ptp(d["foot_R_x"]) < 1e-12
    eng = WalkEngine(ROBOT)
    eng.reset()
    for k in range(1200):
        if k == 200:
            eng.request_stop()
        eng.step(_obs())
    d = eng.diagnostics()
    assert eng.phases[-1].kind == "stand"
    assert abs(d["com_vx"][-1]) < 1e-3 and d["foot_L_x"][-1] == pytest.approx(d["foot_R_x"][-1])


def test_set_command_turns_the_plan():
    eng = WalkEngine(ROBOT)
    eng.reset()
    for k in range(700):
        if k == 100:
            eng.set_command(WalkCommand(0.05, 0.0, 0.4))
        eng.step(_obs())
    yaws = [ph.feet_end["L"][2] for ph in eng.phases if ph.kind == "ss"]
    assert yaws[-1] > 0.5


def test_diagnostics_content():
    eng = WalkEngine(ROBOT)
    eng.reset()
    for _ in range(250):
        eng.step(_obs())
    d = eng.diagnostics()
    for k in WalkEngine.LOG_FIELDS + ("zmp_x", "zmp_y"):
        assert d[k].shape == (250,), k
    assert np.allclose(np.diff(d["t"]), 0.01)
    assert d["footsteps"][0]["kind"] == "stand" and {"t0", "t1", "feet", "zmp0"} <= set(d["footsteps"][1])
    assert d["foot_R_z"].max() == pytest.approx(GaitParams().step_height, rel=1e-6)  # first swing: right foot


def test_load_compensation_straightens_the_support_knee():
    """The static sag offset commands the loaded support knee less bent than the plan."""
    act = ROBOT.actuated_joint_names
    on, off = WalkEngine(ROBOT), WalkEngine(ROBOT, load_compensation=False)
    for e in (on, off):
        e.reset()
    for _ in range(60):
        a_on, a_off = on.step(_obs()), off.step(_obs())
    k = act.index("LKneePitch")
    assert 0.02 < a_off[k] - a_on[k] < 0.2


def test_rejects_bad_params_type():
    with pytest.raises(ValueError, match="GaitParams"):
        WalkEngine(ROBOT, params={"step_period": 0.3})


def test_long_walk_keeps_reference_continuous():
    """Over 90 s the engine's ZMP buffer is compacted; the reference stays continuous and the
    planned CoM stays on the walking line."""
    eng = WalkEngine(ROBOT)
    eng.reset()
    o = _obs()
    for _ in range(9000):
        eng.step(o)
    d = eng.diagnostics()
    assert np.abs(np.diff(d["zmp_ref_x"])).max() < 0.01
    assert np.abs(d["com_y"]).max() < 0.05
    p = GaitParams()
    assert d["com_x"][-1] == pytest.approx(90.0 * p.step_length / p.step_period, rel=0.05)
