"""The identified sim: the diagnosis's effects built into a walking world."""

import numpy as np
import pytest

from envs import SimWorld
from experiments.runtime.fitness import run_walk
from sysid.candidates import Term
from sysid.diagnose import diagnose
from sysid.identified import IdentifiedSimEnv, load_identified
from sysid.report import write_report
from sysid.synthetic import synthetic_logs
from walk_engine import GaitParams


def test_no_terms_is_the_plain_sim_bit_for_bit():
    p = GaitParams.initial()
    a, _ = run_walk(p, seed=3, seconds=2.0, env=SimWorld())
    b, _ = run_walk(p, seed=3, seconds=2.0, env=IdentifiedSimEnv({}))
    for k in a.columns:
        assert np.array_equal(a.columns[k], b.columns[k], equal_nan=True), k


def _step_response(env, joint="LKneePitch", delta=0.2, steps=6):
    """The joint's response to a target step [rad] per control step, minus its sag without one."""
    r = env.robot
    i, j = r.actuated_joint_names.index(joint), r.joint_names.index(joint)
    out = []
    for d in (delta, 0.0):
        env.reset(seed=0)
        a = r.pose("crouch", actuated=True).copy()
        a[i] += d
        out.append(np.array([env.step(a)[0][env.layout["q"]][j] for _ in range(steps)]))
    return out[0] - out[1]


def test_an_injected_latency_is_identified_and_walked_with(tmp_path):
    """Logs of a robot with a 20 ms actuation latency -> diagnosis -> the identified world delays its
    actuators by the identified latency: a target step moves the plain sim's knee within 10 ms, the
    identified sim's only after 20 ms."""
    logs = synthetic_logs({Term("latency"): 0.02}, n_logs=3, seconds=4.0, seed=2)
    rep = diagnose(logs, time_budget_s=60)
    write_report(rep, logs, str(tmp_path / "report"), plots=False)
    terms, rms = load_identified(tmp_path / "report")
    assert abs(terms[Term("latency")] - 0.02) < 1e-3 and rms == 0.0
    env = IdentifiedSimEnv.from_reports([tmp_path / "report" / "report.json"], fixed_base=True)
    assert np.allclose(env.model.actuator_delay, terms[Term("latency")])
    plain = _step_response(SimWorld(fixed_base=True))
    ident = _step_response(env)
    assert plain[0] > 0.03  # the plain knee moves in the first 10 ms
    assert abs(ident[0]) < 1e-6 and abs(ident[1]) < 1e-6 and ident[2] > 0.03  # the identified one after 20 ms
    assert np.allclose(ident[2:], plain[:-2], atol=2e-3)


def test_sensor_bias_and_backlash_act_like_the_real_world():
    """An encoder offset the servo reads too (``encoder_offset``, the real world's calibration offsets):
    the log reads the offset off the physical angle and the servo closes on it; gear play adds a hinge."""
    bias = 0.01
    env = IdentifiedSimEnv({Term("encoder_offset", "LKneePitch"): bias, Term("backlash", "RKneePitch"): 0.004},
                           fixed_base=True)
    r = env.robot
    plain = SimWorld(fixed_base=True)
    a = r.pose("crouch", actuated=True)
    for e in (env, plain):
        e.reset(seed=0)
        for _ in range(50):
            obs, *_ = e.step(a)
        if e is env:
            ident_obs = obs
    j = r.joint_names.index("LKneePitch")
    q_meas = ident_obs[env.layout["q"]][j]
    q_phys = env.data.qpos[env._qadr[j]]
    assert q_meas - q_phys == pytest.approx(bias, abs=1e-9)  # the encoder reads the offset ...
    assert q_meas == pytest.approx(obs[plain.layout["q"]][j], abs=5e-4)  # ... and the servo closes on it (10 mrad off if not)
    obs = ident_obs
    k = r.joint_names.index("RKneePitch")
    assert abs(obs[env.layout["q"]][k] - env.data.qpos[env._qadr[k]]) > 0  # output = motor + play hinge


def test_an_offset_of_the_log_alone_leaves_the_servo_on_the_command():
    """``sensor_bias`` as the diagnosis replays it: the log reads the offset, the servo does not see it."""
    bias = 0.01
    env = IdentifiedSimEnv({Term("sensor_bias", "LKneePitch"): bias}, fixed_base=True)
    plain = SimWorld(fixed_base=True)
    a = env.robot.pose("crouch", actuated=True)
    obs = {}
    for e in (env, plain):
        e.reset(seed=0)
        for _ in range(50):
            obs[e] = e.step(a)[0]
    j = env.robot.joint_names.index("LKneePitch")
    assert obs[env][env.layout["q"]][j] - obs[plain][plain.layout["q"]][j] == pytest.approx(bias, abs=5e-4)
    assert env.data.qpos[env._qadr[j]] == pytest.approx(plain.data.qpos[plain._qadr[j]], abs=5e-4)


def test_identified_ground_is_random_per_episode_with_the_fitted_rms_height():
    env = IdentifiedSimEnv({}, rms_height=0.003)
    env.reset(seed=1)
    h1 = env.terrain.heights.copy()
    env.reset(seed=2)
    h2 = env.terrain.heights.copy()
    env.reset(seed=1)
    assert np.array_equal(env.terrain.heights, h1) and not np.array_equal(h1, h2)
    far = np.hypot(*np.meshgrid(env.terrain.x, env.terrain.y)) > 0.5  # outside the flat start pad
    assert h1[far].std() == pytest.approx(0.003, rel=0.15)
    with pytest.raises(ValueError, match="deterministic"):
        IdentifiedSimEnv({Term("terrain_roughness"): 0.003})


def test_the_sparse_jacobian_on_uneven_ground_solves_the_same_walk(monkeypatch):
    """On its random ground the identified sim builds MuJoCo's constraint Jacobian sparse (faster with
    a sole's many heightfield contacts); the walk is the dense model's to within 0.2 mm of CoM over its
    first second (the same equations, solved to the same tolerance)."""
    import mujoco

    import sysid.identified as identified

    p = GaitParams.initial()
    env = IdentifiedSimEnv({}, rms_height=0.003)
    sparse, _ = run_walk(p, seed=1, seconds=1.0, env=env)
    assert env.model.opt.jacobian == mujoco.mjtJacobian.mjJAC_SPARSE
    assert IdentifiedSimEnv({}).model.opt.jacobian == SimWorld().model.opt.jacobian  # flat: the plain sim's
    monkeypatch.setattr(identified, "GROUND_JACOBIAN", mujoco.mjtJacobian.mjJAC_DENSE)
    env = IdentifiedSimEnv({}, rms_height=0.003)
    dense, _ = run_walk(p, seed=1, seconds=1.0, env=env)
    assert env.model.opt.jacobian == mujoco.mjtJacobian.mjJAC_DENSE
    assert len(sparse) == len(dense) == round(1.0 / env.control_dt)  # neither fell
    com = [np.stack([r.columns[f"gt.com.{a}"] for a in "xyz"], axis=1) for r in (sparse, dense)]
    gap = np.abs(com[0] - com[1]).max()
    assert 0 < gap < 2e-4  # not the same arithmetic, the same walk: 0.08 mm of CoM here


def _stepping_report(compliance_found: bool = False, ground: bool = True) -> dict:
    """A stepping-log report as the diagnosis writes one when a contact term competes with uneven
    ground: the ground declared, the contact term fitted after it (kept uncertain unless found)."""
    comp = {"family": "ground_compliance", "joints": [], "links": [], "value": 0.03, "unit": "s"}
    rough = {"family": "terrain_roughness", "joints": [], "links": [], "value": 0.0025, "unit": "m", "stochastic": True}
    return {"model": {"ground_compliance": 0.03}, "base_model": {"latency": 0.02, "ground_compliance": 0.0025},
            "effects": ([rough] if ground else []) + ([comp] if compliance_found else []),
            "uncertain": [] if compliance_found else [comp],
            "indistinguishable": [{"a": "ground_compliance", "b": "terrain_roughness", "corr": None}] if ground else []}


def test_contact_terms_that_only_stand_in_for_the_ground_can_be_left_out(tmp_path):
    """``confounded=False`` drops an uncertain contact term the report cannot tell apart from its
    declared uneven ground (it would count the ground twice), and nothing else: a found contact
    term, one without a declared ground, and the fixed-base terms stay."""
    import json

    from experiments.runtime.tasks import EpisodeTask
    from experiments.runtime.worlds import world_env
    from sysid.identified import confounded_with_ground
    from walk_engine import GaitParams

    assert confounded_with_ground(_stepping_report()) == {"ground_compliance"}
    assert confounded_with_ground(_stepping_report(compliance_found=True)) == set()
    assert confounded_with_ground(_stepping_report(ground=False)) == set()
    path = tmp_path / "report.json"
    path.write_text(json.dumps(_stepping_report()))
    every, rms = load_identified(path)
    without, rms2 = load_identified(path, confounded=False)
    assert every == {Term("latency"): 0.02, Term("ground_compliance"): 0.03} and rms == rms2 == 0.0025
    assert without == {Term("latency"): 0.02, Term("ground_compliance"): 0.0025}  # the calibrated engine gap's
    # the identified world of the rollout tasks leaves the term out
    task = EpisodeTask("identified", GaitParams().to_array(), 0, identified=(str(path),))
    assert world_env(task).terms[Term("ground_compliance")] == 0.0025
