"""Replay models and batched replay: exactness, timing convention, engine gap, windows."""

import numpy as np
import pytest

from envs import CommandLog, NaoRealEnv, NaoSimEnv, rollout
from envs.effects import get_profile
from envs.mujoco_world import build_model
from robots import nao_h25
from sysid.candidates import Term
from sysid.data import from_recording
from sysid.excitation import protocol
from sysid.model import Structure, base_spec, replay_model
from sysid.replay import predict, whole_logs, windows


@pytest.fixture(scope="module")
def robot():
    return nao_h25()


@pytest.fixture(scope="module")
def cmd(robot):
    return protocol(robot, 3.0, seed=7)


def test_base_spec_matches_build_model(robot):
    a = build_model(robot, fixed_base=True, physics_dt=0.001)
    b = base_spec(robot, fixed_base=True, physics_dt=0.001).compile()
    for f in ("body_mass", "body_inertia", "body_ipos", "jnt_range", "dof_armature", "dof_damping",
              "actuator_gainprm", "actuator_biasprm", "actuator_forcerange", "eq_solref", "geom_friction"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)
    assert a.opt.timestep == b.opt.timestep and a.opt.integrator == b.opt.integrator


def test_replay_of_sim_recording_is_exact(robot, cmd):
    rec = rollout(NaoSimEnv(fixed_base=True), CommandLog(cmd), seed=0, seconds=3.0)
    lg = from_recording(rec, "sim")
    y = predict([lg], whole_logs([lg]), [{}])[0][0]
    assert np.abs(y - lg.q).max() < 1e-9  # history buffers, sensors, timing: bit-for-bit the sim


def test_latency_timing_convention_against_pybullet_fifo(robot, cmd):
    """PyBullet's 20 ms command FIFO is MuJoCo's 20 ms actuator delay: the convention is right."""
    prof = get_profile("none").with_effect("latency_s", 0.02)
    env = NaoRealEnv(fixed_base=True, profile=prof, terrain="flat")
    lg = from_recording(rollout(env, CommandLog(cmd), seed=0, seconds=3.0), "lat")
    env.close()
    out = predict([lg], whole_logs([lg]), [{}, {Term("latency"): 0.02}, {Term("latency"): 0.019}])[0]
    rms = [np.sqrt(np.mean((lg.q - o) ** 2)) for o in out]
    assert rms[1] < 1e-4
    assert rms[2] > 20 * rms[1] and rms[0] > rms[2]


def test_pybullet_none_engine_gap_is_tiny(robot, cmd):
    env = NaoRealEnv(fixed_base=True, profile="none", terrain="flat")
    lg = from_recording(rollout(env, CommandLog(cmd), seed=0, seconds=3.0), "none")
    env.close()
    y = predict([lg], whole_logs([lg]), [{}])[0][0]
    assert np.sqrt(np.mean((y - lg.q) ** 2, axis=0)).max() < 3e-4  # < 0.3 mrad on every joint


def test_backlash_structure_reduces_to_nominal_and_models_are_batched(robot, cmd):
    rec = rollout(NaoSimEnv(fixed_base=True), CommandLog(cmd), seed=0, seconds=3.0)
    lg = from_recording(rec, "sim")
    sets = [{}, {Term("backlash", "LKneePitch"): 0.0}, {Term("backlash", "RAnkleRoll"): 0.0},
            {Term("backlash", "LKneePitch"): 0.03}]
    out = predict([lg], whole_logs([lg]), sets)[0]
    j = robot.joint_names.index("LKneePitch")
    # at zero gap the series hinge is nearly the nominal joint (the servo damping then acts outside
    # the torque clip, which shows only while the torque saturates)
    rms = np.sqrt(np.mean((out[1] - out[0]) ** 2, axis=0))
    assert rms[j] < 3e-3 and np.delete(rms, j).max() < 1e-3
    assert np.sqrt(np.mean((out[2] - out[0]) ** 2, axis=0)).max() < 2e-3
    assert np.sqrt(np.mean((out[3][:, j] - out[0][:, j]) ** 2)) > 5e-3
    rm = replay_model(Structure(play_joints=("LKneePitch",)))
    assert rm.model.nv == 25 and rm.meas.sum() == 25


def test_series_spring_deflects_by_load_times_compliance(robot):
    """A held pose under gravity: a series spring of compliance c adds c * tau_g to the output sag
    (the PD's own sag tau_g / kp is common to both), the stiffest spring is nearly the rigid
    joint, and the replay starts at the measured angle (spring pre-loaded)."""
    import mujoco

    from sysid.model import spring_stiffness_max

    pose = robot.pose("crouch", actuated=True).copy()
    j = robot.joint_names.index("RShoulderPitch")
    pose[robot.actuated_joint_names.index("RShoulderPitch")] = 0.0  # arm held forward: pitch loaded
    cmd = np.tile(pose, (150, 1))
    lg = from_recording(rollout(NaoSimEnv(fixed_base=True), CommandLog(cmd), seed=0, seconds=1.5), "hold")
    c = 0.05
    k_max = spring_stiffness_max(True)["RShoulderPitch"]
    out = predict([lg], whole_logs([lg]), [{}, {Term("joint_compliance", "RShoulderPitch"): c},
                                           {Term("joint_compliance", "RShoulderPitch"): 1.0 / k_max}])[0]
    assert abs(out[1][0, j] - lg.q[0, j]) < 1e-9  # starts at the measured output angle
    rm = replay_model(Structure())
    m = rm.model
    d = mujoco.MjData(m)
    d.qpos[rm.qadr] = out[0][-1]
    mujoco.mj_forward(m, d)
    tau_g = float(d.qfrc_bias[rm.dadr[j]])  # gravity torque the joint holds at the end [N m]
    assert abs(tau_g) > 0.05
    sag = out[1][-1, j] - out[0][-1, j]
    assert abs(sag - (-c * tau_g)) < 0.1 * abs(c * tau_g)
    assert np.abs(out[2][-60:, j] - out[0][-60:, j]).max() < 0.1 * abs(c * tau_g)
    assert np.delete(np.abs(out[1][-1] - out[0][-1]), j).max() < 0.1 * abs(sag)


def test_windowed_replay_of_floating_sim_log_is_exact(robot):
    env = NaoSimEnv(fixed_base=False)
    c = np.tile(robot.pose("crouch", actuated=True), (150, 1))
    c[:, robot.actuated_joint_names.index("LShoulderPitch")] += 0.3 * np.sin(np.linspace(0, 6, 150))
    lg = from_recording(rollout(env, CommandLog(c), seed=0, seconds=1.5), "float")
    assert not lg.fixed_base
    wins = windows([lg], [0], 0.5)
    assert [w.length for w in wins] == [50, 50, 50]
    out = predict([lg], wins, [{}], with_imu=True)
    for w, o in zip(wins, out):
        assert np.abs(o[0, :, :24] - lg.q[w.k0:w.k1]).max() < 1e-3
        # contact warm-start is not part of a recording: windows agree to ~1 mrad, not bit for bit
        assert np.abs(o[0, :, 24:26] - lg.imu["angle"][w.k0:w.k1]).max() < 3e-3
        assert np.abs(o[0, :, 26:29] - lg.imu["gyro"][w.k0:w.k1]).max() < 0.05


def test_floating_base_state_estimate_without_ground_truth(robot):
    """Logs without gt.* columns: the torso state comes from IMU angles, gyro and leg kinematics."""
    from sysid.estimate import base_state

    env = NaoSimEnv(fixed_base=False)
    c = np.tile(robot.pose("crouch", actuated=True), (100, 1))
    lg = from_recording(rollout(env, CommandLog(c), seed=0, seconds=1.0), "float")
    for k in (0, 50, 99):
        est = base_state(lg, k)
        assert abs(est["pos"][2] - lg.gt["gt.base"][k, 2]) < 3e-3
        assert abs(abs(float(est["quat"] @ lg.gt["gt.quat"][k])) - 1.0) < 1e-4  # same tilt (yaw 0 here)
        assert np.abs(est["linvel"] - lg.gt["gt.vel"][k]).max() < 0.02
    lg.gt = {}
    wins = windows([lg], [0], 0.5)
    out = predict([lg], wins, [{}], with_imu=True)
    assert np.abs(out[0][0, :, :24] - lg.q[:50]).max() < 5e-3


def test_localisation_pairs_each_window_with_its_own_log():
    """Logs cut into several windows (the diagnosis's 0.5 s windows) of logs of different lengths:
    every window's residual is its own log's (here a known offset per log), none is dropped."""
    from sysid.data import Log
    from sysid.replay import windows
    from sysid.stats import localisation

    rng = np.random.default_rng(3)
    n, dt, offsets = 3, 0.01, (0.01, -0.03)
    logs = []
    for i, N in enumerate((150, 149)):  # one sample short, as a log cut at a fall
        q = rng.normal(0, 0.1, (N, n))
        logs.append(Log(name=f"log{i}", t=np.arange(N) * dt, cmd=q.copy(), q=q, dq=None, control_dt=dt,
                        physics_dt=0.002, fixed_base=True))
    wins = windows(logs, [0, 1], 0.5)
    assert len(wins) == 6 and {w.log for w in wins} == {0, 1}
    y_sim = [logs[w.log].q[w.k0:w.k1] - offsets[w.log] for w in wins]
    loc = localisation(logs, wins, y_sim, np.full(n, 0.01), ["a", "b", "c"])
    rows = [w.length - 1 for w in wins]  # the first row of each window is its initial state
    want = sum(r * offsets[w.log] for r, w in zip(rows, wins)) / sum(rows)
    for name in "abc":
        assert loc["channels"][name]["bias"] == pytest.approx(want)
        assert loc["channels"][name]["rms"] == pytest.approx(np.sqrt(sum(r * offsets[w.log] ** 2 for r, w in zip(rows, wins)) / sum(rows)))
    with pytest.raises(ValueError, match="windows"):
        localisation(logs, wins, y_sim[:-1], np.full(n, 0.01), ["a", "b", "c"])
