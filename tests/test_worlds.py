"""The two worlds: engine agreement, standing, determinism, gymnasium API, bad input."""

import mujoco
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from envs import CommandLog, HoldPose, RealWorld, SimWorld, rollout
from envs.excitation import chirp_with_holds
from robots import nao_h25
from terrain import lumpy


def replay(env, commands, seed=0):
    rec = rollout(env, CommandLog(commands), seed=seed, seconds=len(commands) * env.control_dt)
    return rec


def test_fixed_base_chirp_agrees_across_engines():
    """Same URDF, same PD, same 1 ms step, no armature: the 6 s chirp+holds replay differs by
    physics only (<= 3 mrad RMS per joint)."""
    robot = nao_h25()
    cmd = chirp_with_holds(robot, seconds=6.0)
    q_sim = replay(SimWorld(fixed_base=True), cmd).group("q")
    real = RealWorld(fixed_base=True, profile="none")
    q_real = replay(real, cmd).group("q")
    real.close()
    assert q_sim.shape == q_real.shape == (600, 24)
    moved = np.ptp(q_sim, axis=0)
    assert np.all(moved[robot.joint_index(robot.groups["legs"])] > 0.05)  # the replay excites the legs
    rms = np.sqrt(((q_sim - q_real) ** 2).mean(0))
    assert rms.max() <= 3e-3, dict(zip(robot.joint_names, np.round(rms * 1e3, 3)))


@pytest.mark.parametrize("world", ["sim", "real"])
@pytest.mark.parametrize("amplitude", [0.0, 0.01])
def test_crouch_stands_10s(world, amplitude):
    hf = lumpy(3, amplitude=amplitude) if amplitude > 0 else None
    env = SimWorld(terrain=hf) if world == "sim" else RealWorld(profile="none", terrain=hf if hf else "flat")
    rec = rollout(env, HoldPose(env.robot, "crouch"), seed=0, seconds=10.0)
    assert not rec.fell, rec.meta["fall_reason"]
    assert len(rec) == 1000
    com = rec.group("gt.com")
    assert np.linalg.norm(com[-1, :2] - com[0, :2]) < 0.02
    fsr = rec.group("fsr")[-100:].mean(0)  # both feet carry the robot (5.3 kg * 9.81 = 52 N)
    assert fsr.sum() == pytest.approx(nao_h25().total_mass * 9.81, rel=0.05)
    assert fsr.min() > 15.0
    env.close()


def test_real_profile_stands_too():
    env = RealWorld(profile="real")
    rec = rollout(env, HoldPose(env.robot), seed=1, seconds=5.0)
    assert not rec.fell
    assert rec.meta["terrain"] is not None and rec.meta["terrain"]["max"] > 0.004  # a lumpy field
    env.close()


def test_mujoco_bit_identical():
    cmd = chirp_with_holds(nao_h25(), seconds=3.0, amplitude=0.1)
    a = replay(SimWorld(), cmd)
    b = replay(SimWorld(), cmd)
    for k in a.columns:
        assert np.array_equal(a.columns[k], b.columns[k], equal_nan=True), k


def test_pybullet_same_seed_identical_different_seed_differs():
    cmd = chirp_with_holds(nao_h25(), seconds=3.0, amplitude=0.1)
    env = RealWorld(profile="real")
    a = replay(env, cmd, seed=5)
    b = replay(env, cmd, seed=6)
    c = replay(RealWorld(profile="real"), cmd, seed=5)  # a fresh process-level world, same seed
    d = replay(env, cmd, seed=5)  # the same world again after another episode
    for k in a.columns:
        assert np.array_equal(a.columns[k], c.columns[k], equal_nan=True), k
        assert np.array_equal(a.columns[k], d.columns[k], equal_nan=True), k
    assert a.meta["terrain"] != b.meta["terrain"]
    assert a.meta["effects"] != b.meta["effects"]
    assert not np.array_equal(a.group("q"), b.group("q"))


@pytest.mark.parametrize("make", [lambda: SimWorld(), lambda: RealWorld(profile="real")], ids=["sim", "real"])
def test_check_env(make):
    env = make()
    check_env(env, skip_render_check=True)
    env.close()


@pytest.mark.parametrize("make", [lambda: SimWorld(), lambda: RealWorld(profile="none")], ids=["sim", "real"])
def test_bad_actions(make):
    env = make()
    obs, info = env.reset(seed=0)
    assert set(info) >= {"base_pos", "base_quat", "com", "base_linvel"}
    assert obs.shape == env.observation_space.shape
    a = env.robot.pose("crouch", actuated=True)
    with pytest.raises(ValueError, match="shape"):
        env.step(a[:5])
    bad = a.copy()
    bad[env.robot.actuated_joint_names.index("LKneePitch")] = np.nan
    with pytest.raises(ValueError, match="LKneePitch"):
        env.step(bad)
    bad[:] = a
    bad[0] = np.inf
    with pytest.raises(ValueError, match="HeadYaw"):
        env.step(bad)
    # out-of-range targets are clipped to the joint limits, not rejected
    _, _, _, _, info = env.step(a + 10.0)
    assert np.all(info["applied_action"] <= env.action_space.high)
    env.close()


def test_unknown_profile_and_terrain():
    with pytest.raises(ValueError, match="unknown profile 'moon'"):
        RealWorld(profile="moon")
    with pytest.raises(ValueError, match="terrain"):
        RealWorld(terrain="ice")
    with pytest.raises(ValueError, match="terrain"):
        SimWorld(terrain=3)


def test_nan_physics_state_ends_episode_unstable_sim(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # MuJoCo logs its warning to MUJOCO_LOG.TXT in the working directory
    env = SimWorld()
    env.reset(seed=0)
    env.data.qvel[:] = np.nan  # corrupt the physics state
    obs, r, terminated, truncated, info = env.step(env.robot.pose("crouch", actuated=True))
    assert terminated and info["fall_reason"] == "unstable"
    assert np.all(np.isfinite(obs))
    with pytest.raises(RuntimeError, match="reset"):
        env.step(env.robot.pose("crouch", actuated=True))
    env.reset(seed=0)  # and the world recovers
    _, _, terminated, _, info = env.step(env.robot.pose("crouch", actuated=True))
    assert not terminated


def test_nan_physics_state_ends_episode_unstable_real():
    env = RealWorld(profile="none", terrain="flat")
    env.reset(seed=0)
    env.client.resetJointState(env.body, env._jidx[3], float("nan"), 0.0)  # corrupt one joint
    obs, r, terminated, truncated, info = env.step(env.robot.pose("crouch", actuated=True))
    assert terminated and info["fall_reason"] == "unstable"
    assert np.all(np.isfinite(obs))
    env.reset(seed=0)
    _, _, terminated, _, _ = env.step(env.robot.pose("crouch", actuated=True))
    assert not terminated
    env.close()


def test_fall_is_detected_with_reason():
    env = SimWorld()
    obs, info = env.reset(seed=0)
    a = env.robot.pose("crouch", actuated=True).copy()
    names = env.robot.actuated_joint_names
    a[names.index("LHipPitch")] = a[names.index("RHipPitch")] = -1.5  # jack-knife forward
    rec = rollout(env, lambda o: a, seed=0, seconds=5.0)
    assert rec.fell and rec.meta["fall_reason"] in ("tilt", "torso_low")
    assert 0 < rec.meta["fall_time"] < 5.0


def test_real_world_reports_the_torso_link_frame_not_bullets_inertial_frame():
    """Bullet's base pose is the torso's centre-of-mass frame rotated onto its principal axes (for a
    free base; roll -19, pitch +23, yaw +74 mrad here). The state must be the URDF torso frame: the
    robot is loaded upright, and standing in the crouch both engines' IMU angles agree (an earlier
    version read the inertial frame: a 20 mrad roll offset and a gyro rotated by 74 mrad)."""
    real = RealWorld(profile="none", terrain="flat")
    _, info = real.reset(seed=0)
    assert np.abs(info["base_quat"] - [1.0, 0.0, 0.0, 0.0]).max() < 1e-9
    rec_real = rollout(real, HoldPose(real.robot, "crouch"), seed=0, seconds=2.0)
    real.close()
    sim = SimWorld()
    rec_sim = rollout(sim, HoldPose(sim.robot, "crouch"), seed=0, seconds=2.0)
    d_angle = rec_real.group("angle")[-50:].mean(0) - rec_sim.group("angle")[-50:].mean(0)
    assert np.abs(d_angle).max() < 3e-3, d_angle  # measured 1.6 mrad in pitch, 0 in roll
    assert np.abs(rec_real.group("gt.base")[-1] - rec_sim.group("gt.base")[-1]).max() < 2e-3


@pytest.mark.parametrize("world", ["sim", "real"])
def test_fixed_base_hangs_and_never_falls(world):
    env = SimWorld(fixed_base=True) if world == "sim" else RealWorld(fixed_base=True, profile="real")
    _, info = env.reset(seed=0)
    assert info["base_pos"][2] == pytest.approx(0.6)
    if world == "sim":
        assert env.model.nq == 24 and not any(env.model.jnt_type == mujoco.mjtJoint.mjJNT_FREE)
    rec = rollout(env, lambda o: env.robot.pose("zero", actuated=True), seed=0, seconds=1.0)
    assert not rec.fell and np.all(rec.group("fsr") == 0)
    assert np.abs(rec.group("gt.base") - [0.0, 0.0, 0.6]).max() < 1e-9  # the base stays where it hangs
    env.close()


@pytest.mark.parametrize("ground", ["plane", "heightfield"])
def test_real_world_foot_friction_is_the_contact_coefficient(ground):
    """Bullet multiplies the two bodies' friction coefficients; the real world's ground is 1, so a
    foot friction of 0.3 is a contact coefficient of 0.3 (it was 0.3^2 = 0.09): a block with the
    feet's coefficient sticks at tan(slope) = 0.25 and slides at 0.36 (slope made by tilting gravity)."""
    import pybullet

    from terrain import flat

    env = RealWorld(fixed_base=False, profile={"foot_friction": (0.3, 0.3)})
    env.reset(seed=0, options={"terrain": None if ground == "plane" else flat()})
    p = env.client
    foot = env._link[env.robot.frames["l_sole"].link]
    mu = p.getDynamicsInfo(env.body, foot)[1]
    assert mu == pytest.approx(0.3)
    p.removeBody(env.body)
    slid = {}
    for tan in (0.25, 0.36):
        box = p.createMultiBody(1.0, p.createCollisionShape(pybullet.GEOM_BOX, halfExtents=[0.05] * 3),
                                basePosition=[0.0, 0.0, 0.0505])
        p.changeDynamics(box, -1, lateralFriction=mu)
        a = np.arctan(tan)
        p.setGravity(9.81 * np.sin(a), 0.0, -9.81 * np.cos(a))
        for _ in range(1000):
            p.stepSimulation()
        slid[tan] = p.getBasePositionAndOrientation(box)[0][0]
        p.removeBody(box)
    env.close()
    assert abs(slid[0.25]) < 2e-3 and slid[0.36] > 0.05


def test_recorded_terrain_spec_rebuilds_the_episode_field(tmp_path):
    """A recording's metadata is enough to rebuild the field its episode ran on (terrain.from_spec):
    the real world's per-episode lumpy field, and a field given to the sim."""
    from envs import Recording
    from terrain import from_spec, make

    env = RealWorld(profile="real")
    for seed in (2, 7):
        rec = rollout(env, HoldPose(env.robot), seed=seed, seconds=0.05)
        spec = rec.meta["terrain"]["spec"]
        assert spec["generator"] == "lumpy" and spec["seed"] == {"entropy": seed, "spawn_key": [1]}
        assert spec["amplitude"] == rec.meta["effects"]["terrain_amplitude"]
        back = Recording.from_parquet(rec.to_parquet(tmp_path / f"real{seed}.parquet"))
        assert np.array_equal(from_spec(back.meta["terrain"]["spec"]).heights, env.terrain.heights)
    env.close()
    hf = make("fractal", seed=5, amplitude=0.02)
    rec = rollout(SimWorld(terrain=hf), HoldPose(nao_h25()), seed=0, seconds=0.05)
    assert np.array_equal(from_spec(rec.meta["terrain"]["spec"]).heights, hf.heights)
