"""Each real-world effect, switched on alone, measurably changes a replay; "none" changes nothing."""

import numpy as np
import pytest

from envs import EFFECTS, PROFILES, CommandLog, RealWorld, SimWorld, RealProfile, get_profile, rollout
from envs.excitation import chirp_with_holds
from robots import nao_h25

ROBOT = nao_h25()
CMD = chirp_with_holds(ROBOT, seconds=3.0, hold=0.5, amplitude=0.2)
# effects seen on a hanging robot, with the observation group where they show
FIXED_BASE = {
    "kp_scale": ((0.7, 0.7), "q"), "kd_scale": ((2.0, 2.0), "q"), "latency_s": ((0.02, 0.02), "q"),
    "backlash_rad": ((0.01, 0.01), "q"), "coulomb_friction_nm": ((0.1, 0.1), "q"),
    "viscous_damping": ((0.05, 0.05), "q"), "torque_limit_scale": ((0.5, 0.5), "q"),
    "mass_scale": ((1.3, 1.3), "q"), "encoder_bias_rad": ((0.01, 0.01), "q"),
    "encoder_noise_rad": ((0.002, 0.002), "q"), "gyro_bias": ((0.02, 0.02), "gyro"),
    "gyro_noise": ((0.01, 0.01), "gyro"), "accel_noise": ((0.1, 0.1), "acc"),
    "angle_noise_rad": ((0.005, 0.005), "angle"),
}
# effects that need the feet on the ground
ON_GROUND = {"foot_friction": (0.05, 0.05), "terrain_amplitude": (0.02, 0.02)}


def _replay(profile, fixed_base=True, seed=0, cmd=CMD):
    env = RealWorld(profile=profile, fixed_base=fixed_base)
    rec = rollout(env, CommandLog(cmd), seed=seed, seconds=len(cmd) * env.control_dt)
    env.close()
    return rec


@pytest.fixture(scope="module")
def baseline():
    return _replay("none")


def test_every_effect_is_covered():
    assert set(FIXED_BASE) | set(ON_GROUND) == set(EFFECTS)


@pytest.mark.parametrize("effect", sorted(FIXED_BASE))
def test_effect_changes_fixed_base_replay(effect, baseline):
    value, group = FIXED_BASE[effect]
    rec = _replay(PROFILES["none"].with_effect(effect, value))
    assert not rec.fell
    diff = np.abs(rec.group(group) - baseline.group(group))
    assert diff.max() > 1e-3, f"{effect} changed {group} by only {diff.max():.2e}"
    # an actuator effect moves the joints, a sensor effect changes only what is measured
    if group != "q" or effect.startswith("encoder"):
        assert np.array_equal(rec.group("gt.base"), baseline.group("gt.base"))
    if effect.startswith(("gyro", "accel", "angle")):
        assert np.array_equal(rec.group("q"), baseline.group("q"))


@pytest.mark.parametrize("effect", sorted(ON_GROUND))
def test_effect_changes_standing_replay(effect):
    cmd = chirp_with_holds(ROBOT, seconds=3.0, hold=0.5, f1=2.0, amplitude=0.03, joints=list(ROBOT.groups["legs"]))
    base = _replay("none", fixed_base=False, cmd=cmd)
    rec = _replay(PROFILES["none"].with_effect(effect, ON_GROUND[effect]), fixed_base=False, cmd=cmd)
    assert not base.fell
    n = min(len(base), len(rec))
    d = np.abs(rec.group("gt.base")[:n] - base.group("gt.base")[:n]).max()
    assert d > 1e-3, f"{effect} moved the torso by only {d:.2e} m"


def test_none_profile_changes_nothing(baseline):
    prof = get_profile("none")
    assert prof.is_identity and prof.active() == []
    draw = prof.draw(np.random.default_rng(3), 24, 25)
    assert np.all(draw.kp_scale == 1) and draw.latency_s == 0 and np.all(draw.backlash_rad == 0)
    other_seed = _replay("none", seed=99)
    for k in baseline.columns:  # no randomness at all
        assert np.array_equal(baseline.columns[k], other_seed.columns[k], equal_nan=True), k
    sim = rollout(SimWorld(fixed_base=True), CommandLog(CMD), seed=0, seconds=3.0)
    assert np.abs(sim.group("q") - baseline.group("q")).max() < 3e-3  # only the engine gap is left


def test_real_profile_draws_within_ranges_per_seed():
    prof = get_profile("real")
    assert set(prof.active()) == set(EFFECTS)
    a = prof.draw(np.random.default_rng(1), 24, 25)
    b = prof.draw(np.random.default_rng(2), 24, 25)
    lo, hi = prof.latency_s
    assert lo <= a.latency_s <= hi and a.latency_s != b.latency_s
    assert a.kp_scale.shape == (24,) and np.all((a.kp_scale >= prof.kp_scale[0]) & (a.kp_scale <= prof.kp_scale[1]))


def test_profile_validation():
    with pytest.raises(ValueError, match="latency_s"):
        RealProfile(latency_s=(-0.01, 0.0))
    with pytest.raises(ValueError, match="kp_scale"):
        RealProfile(kp_scale=(1.0, 0.5))
    with pytest.raises(ValueError, match="unknown effect"):
        RealProfile.from_dict({"warp_drive": (0, 1)})
    with pytest.raises(ValueError, match="unknown effect"):
        PROFILES["none"].with_effect("warp_drive", 1.0)
    assert RealProfile.from_dict(PROFILES["real"].to_dict()) == PROFILES["real"]


def test_real_splits_into_flat_and_ground():
    """"real-flat" draws "real"'s effects on the same seed on flat ground; "real-ground" only its ground."""
    n_j, n_l = len(ROBOT.joint_names), len(ROBOT.links)
    draw = {name: get_profile(name, ROBOT).draw(np.random.default_rng(7), n_j, n_l)
            for name in ("real", "real-flat", "real-ground", "none")}
    assert draw["real"].terrain_amplitude > 0.0
    assert draw["real-flat"].terrain_amplitude == 0.0
    assert draw["real-ground"].terrain_amplitude == draw["real"].terrain_amplitude
    for f in EFFECTS:
        if f != "terrain_amplitude":
            np.testing.assert_array_equal(getattr(draw["real-flat"], f), getattr(draw["real"], f), err_msg=f)
            np.testing.assert_array_equal(getattr(draw["real-ground"], f), getattr(draw["none"], f), err_msg=f)
    # the flat profile walks on a plane, the ground profile on a heightfield
    env = RealWorld(profile="real-flat")
    env.reset(seed=3)
    assert env._terrain is None
    env.close()
    env = RealWorld(profile="real-ground")
    env.reset(seed=3)
    assert env._terrain is not None and float(np.ptp(env._terrain.heights)) > 0.0
    env.close()
    with pytest.raises(ValueError, match="real-flat"):
        get_profile("real-flatt")
