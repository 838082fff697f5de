"""The floating-base excitation protocol on a standing robot: its ``slip`` segment makes the feet
slide on a slippery floor and not on a grippy one, and the robot stays up."""

import numpy as np
import pytest

from envs import NaoSimEnv
from robots import nao_h25
from sysid.excitation import protocol

SLIP_SECONDS = 1.7  # the slip segment: first after the 0.4 s start hold (~1.2 s of a 6 s log)


def _sole_slide(friction: float, seed: int) -> tuple[np.ndarray, bool]:
    """How far each sole slid on the floor in the first :data:`SLIP_SECONDS` of a 6 s floating
    protocol log in the sim (xy path [m] while the foot bears > 10 N and lies flat), and whether
    the robot fell in the whole log."""
    env = NaoSimEnv(fixed_base=False, friction=friction)
    cmd = protocol(env.robot, 6.0, seed=seed, control_dt=env.control_dt, fixed_base=False)
    obs, _ = env.reset(seed=seed, options={"pose": "crouch"})
    soles = [env.data.site(s) for s in ("l_sole", "r_sole")]
    prev = [s.xpos.copy() for s in soles]
    path = np.zeros(2)
    for k, a in enumerate(cmd):
        loaded = obs[env.layout["fsr"]] > 10.0
        obs, _, terminated, _, _ = env.step(a)
        if terminated:
            return path, True
        for i, s in enumerate(soles):
            p = s.xpos.copy()
            if k * env.control_dt < SLIP_SECONDS and loaded[i] and max(p[2], prev[i][2]) < 1.5e-3:
                path[i] += np.linalg.norm(p[:2] - prev[i][:2])
            prev[i] = p
    return path, False


@pytest.mark.parametrize("seed", [0, 3])
def test_slip_segment_slides_feet_on_a_slippery_floor_only(seed):
    """μ 0.25 vs 0.8: the soles slide >= 20 mm more (measured 39-51 mm vs 0.5 mm at seeds 0 and 3;
    the protocol without the slip segment: 2-5 mm); no fall down to μ 0.15."""
    slide = {}
    for mu in (0.15, 0.25, 0.8):
        path, fell = _sole_slide(mu, seed)
        assert not fell, f"fell at friction {mu}"
        slide[mu] = path
    assert np.all(slide[0.25] - slide[0.8] > 0.020), slide
    assert np.all(slide[0.8] < 0.006), slide  # creep of MuJoCo's soft friction (12 mm with impratio 1)


def test_floating_protocol_starts_with_the_slip_segment():
    """A standing robot's log starts (after the 0.4 s hold) with the legs apart/together."""
    r = nao_h25()
    a = protocol(r, 6.0, seed=0, fixed_base=False)
    names = list(r.actuated_joint_names)
    lh, rh = names.index("LHipRoll"), names.index("RHipRoll")
    spread = a[40:162, lh] - a[40:162, rh]  # hips rolling in opposition: legs apart/together
    assert np.ptp(spread) > 0.05
    b = protocol(r, 6.0, seed=1, fixed_base=False)
    assert not np.allclose(a[40:162], b[40:162])  # seeds give different slip segments


def _saturated_steps(segments) -> tuple[np.ndarray, np.ndarray]:
    """Per joint: control steps of a 4 s fixed-base sim log whose PD torque demand
    kp (q* - q) - kd q̇ (at the start of the step) exceeds the effort limit, and the largest applied
    actuator force over the effort (MuJoCo clips it at ``forcerange``)."""
    env = NaoSimEnv(fixed_base=True)
    r = env.robot
    cmd = protocol(r, 4.0, seed=3, segments=segments, control_dt=env.control_dt)
    env.reset(seed=0)
    eff, kp, kd = np.asarray(r.effort), np.asarray(r.kp), np.asarray(r.kd)
    joints = [env.data.joint(n) for n in r.joint_names]
    count = np.zeros(len(joints), int)
    peak = np.zeros(len(joints))
    for a, tgt in zip(cmd, r.expand_action(cmd)):
        q = np.array([j.qpos[0] for j in joints])
        qd = np.array([j.qvel[0] for j in joints])
        count += np.abs(kp * (tgt - q) - kd * qd) > eff
        env.step(a)
        peak = np.maximum(peak, np.abs(env.data.actuator_force) / eff)
    return count, peak


def test_saturation_segment_drives_every_joint_into_its_torque_limit():
    sat, peak = _saturated_steps(("saturation",))
    default, _ = _saturated_steps(("holds", "ramps", "steps", "reversals", "gait", "chirp"))
    assert (sat >= 3).all(), dict(zip(nao_h25().joint_names, sat))  # every joint, at several steps
    assert (default >= 3).sum() < len(default) // 2  # the default protocol leaves most joints unsaturated
    assert (peak > 0.999).sum() >= len(peak) // 3  # the clipped torque is what the joints get


def test_saturation_segment_refuses_a_floating_base():
    with pytest.raises(ValueError, match="fixed base"):
        protocol(nao_h25(), 4.0, segments=("holds", "saturation"), fixed_base=False)
