"""Leg kinematics: NumPy FK agrees with MuJoCo on the robot model; the analytic IK is exact."""

import numpy as np
import pytest

import envs
from robots import nao_h25
from robots.kinematics import BodyModel
from walk_engine.kinematics import (LEG_JOINTS, LEG_REACH, REACH_CLIP, hip_offset, leg_fk, leg_ik,
                                    leg_ik_fixed_hyp, leg_limits, leg_load_torques, legs_ik)


@pytest.fixture(scope="module")
def hanging():
    env = envs.SimWorld(fixed_base=True)
    env.reset(seed=0)
    yield env
    env.close()


def _random_q(robot, rng):
    q = rng.uniform(robot.lower, robot.upper)
    names = robot.joint_names
    q[names.index("RHipYawPitch")] = q[names.index("LHipYawPitch")]  # one motor
    return q


def _torso_relative(env, site):
    d = env.data
    tp, tR = d.xpos[env._torso], d.xmat[env._torso].reshape(3, 3)
    return tR.T @ (d.site_xpos[env._sites[site]] - tp), tR.T @ d.site_xmat[env._sites[site]].reshape(3, 3)


def test_fk_matches_mujoco_model(hanging):
    """Our FK of the sole frames = MuJoCo's l_sole/r_sole sites relative to the torso."""
    r = hanging.robot
    rng = np.random.default_rng(1)
    for _ in range(200):
        q = _random_q(r, rng)
        hanging.set_state(q)
        for side, site in (("L", "l_sole"), ("R", "r_sole")):
            p, R = leg_fk(side, q[r.joint_index([side + j for j in LEG_JOINTS])])
            pm, Rm = _torso_relative(hanging, site)
            np.testing.assert_allclose(p, pm, atol=1e-12)
            np.testing.assert_allclose(R, Rm, atol=1e-12)


def test_body_com_matches_mujoco(hanging):
    r = hanging.robot
    body = BodyModel(r)
    rng = np.random.default_rng(2)
    for _ in range(20):
        q = _random_q(r, rng)
        hanging.set_state(q)
        d = hanging.data
        tR = d.xmat[hanging._torso].reshape(3, 3)
        com_m = tR.T @ (d.subtree_com[hanging._torso] - d.xpos[hanging._torso])
        np.testing.assert_allclose(body.com(q), com_m, atol=1e-12)


def test_ik_on_mujoco_poses(hanging):
    """IK of sole poses measured in MuJoCo gives angles whose MuJoCo poses are the targets."""
    r = hanging.robot
    rng = np.random.default_rng(3)
    iL = r.joint_index(["L" + j for j in LEG_JOINTS])
    iR = r.joint_index(["R" + j for j in LEG_JOINTS])
    for _ in range(30):
        q = r.pose("crouch") + rng.normal(0, 0.15, 24)
        q[r.joint_names.index("RHipYawPitch")] = q[r.joint_names.index("LHipYawPitch")]
        q = np.clip(q, r.lower, r.upper)
        q[iL[3]] = max(q[iL[3]], 0.2)
        q[iR[3]] = max(q[iR[3]], 0.2)
        hanging.set_state(q)
        (pL, RL), (pR, RR) = _torso_relative(hanging, "l_sole"), _torso_relative(hanging, "r_sole")
        qL, qR, _ = legs_ik(pL, RL, pR, RR, 0.5)
        q2 = q.copy()
        q2[iL], q2[iR] = qL, qR
        hanging.set_state(q2)
        for site, (p, R) in (("l_sole", (pL, RL)), ("r_sole", (pR, RR))):
            pm, Rm = _torso_relative(hanging, site)
            np.testing.assert_allclose(pm, p, atol=1e-9)
            np.testing.assert_allclose(Rm, R, atol=1e-9)


def _reachable_poses(n, rng):
    """Random joint configurations within the limits, knee >= 0.1 rad (inside the IK's reach
    clip of 0.999 (thigh + tibia)), both legs sharing HipYawPitch; and their sole poses."""
    r = nao_h25()
    out = []
    for _ in range(n):
        qs = {}
        for side in "LR":
            lo, hi = leg_limits(r, side)
            q = rng.uniform(lo, hi)
            q[3] = rng.uniform(0.1, hi[3])
            qs[side] = q
        qs["R"][0] = qs["L"][0]
        out.append((qs, {s: leg_fk(s, qs[s]) for s in "LR"}))
    return out


def _rot_err(R1, R2):
    c = (np.trace(R1.T @ R2) - 1.0) / 2.0
    return float(np.arccos(np.clip(c, -1.0, 1.0))) if c < 1 - 1e-12 else float(np.linalg.norm(R1 - R2))


def test_ik_reproduces_2000_random_reachable_poses():
    rng = np.random.default_rng(4)
    worst_p = worst_r = 0.0
    for qs, poses in _reachable_poses(2000, rng):
        (pL, RL), (pR, RR) = poses["L"], poses["R"]
        w = rng.uniform()
        qL, qR, hyp = legs_ik(pL, RL, pR, RR, w)  # shared HipYawPitch
        assert qL[0] == qR[0] == hyp
        for side, q, (p, R) in (("L", qL, poses["L"]), ("R", qR, poses["R"])):
            p2, R2 = leg_fk(side, q)
            worst_p = max(worst_p, np.abs(p2 - p).max())
            worst_r = max(worst_r, _rot_err(R, R2))
            q6 = leg_ik(side, p, R)  # unconstrained 6-DoF solution
            p3, R3 = leg_fk(side, q6)
            worst_p = max(worst_p, np.abs(p3 - p).max())
            worst_r = max(worst_r, _rot_err(R, R3))
    assert worst_p < 1e-9 and worst_r < 1e-9, (worst_p, worst_r)


def test_fixed_hyp_keeps_position_and_sole_normal():
    """With a HipYawPitch that differs from the pose's, the ankle position and sole normal are
    still exact (only the yaw about the sole normal is left open)."""
    rng = np.random.default_rng(5)
    r = nao_h25()
    lo, hi = leg_limits(r, "L")
    for _ in range(500):
        q = rng.uniform(lo, hi)
        q[3] = rng.uniform(0.3, 1.5)
        q[0] = rng.uniform(-0.3, 0.3)
        q[1] = rng.uniform(-0.2, 0.3)
        p, R = leg_fk("L", q)
        q2 = leg_ik_fixed_hyp("L", p, R, q[0] + rng.uniform(-0.1, 0.1))
        pa, Ra = leg_fk("L", q2, "ankle")
        np.testing.assert_allclose(pa, leg_fk("L", q, "ankle")[0], atol=1e-9)
        np.testing.assert_allclose(Ra[:, 2], R[:, 2], atol=1e-9)


def test_unreachable_targets_are_clipped_without_nan():
    rng = np.random.default_rng(6)
    for side in "LR":
        hip = hip_offset(side)
        for _ in range(300):
            direction = rng.normal(size=3)
            direction /= np.linalg.norm(direction)
            dist = rng.choice([0.0, 1e-6, 0.25, 0.5, 3.0])
            R = np.linalg.qr(rng.normal(size=(3, 3)))[0]
            R *= np.sign(np.linalg.det(R))
            p = hip + direction * dist
            for q in (leg_ik(side, p, R), leg_ik_fixed_hyp(side, p, R, 0.1), legs_ik(p, R, p, R)[0]):
                assert np.all(np.isfinite(q))
                pa, _ = leg_fk(side, q, "ankle")
                assert np.linalg.norm(pa - hip) <= REACH_CLIP * LEG_REACH + 1e-9
    # straight down beyond reach: the leg is stretched (knee nearly straight) towards the target
    q = leg_ik("L", np.array([0.0, 0.05, -1.0]), np.eye(3))
    assert q[3] == pytest.approx(0.0, abs=0.1) and np.all(np.isfinite(q))


def test_load_torques_match_mujoco_jacobian(hanging):
    import mujoco

    r, m, d = hanging.robot, hanging.model, hanging.data
    rng = np.random.default_rng(7)
    for _ in range(50):
        q = _random_q(r, rng)
        hanging.set_state(q)
        tp, tR = d.xpos[hanging._torso], d.xmat[hanging._torso].reshape(3, 3)
        for side, body in (("L", "l_ankle"), ("R", "r_ankle")):
            idx = r.joint_index([side + j for j in LEG_JOINTS])
            p, _ = leg_fk(side, q[idx])
            cop, F = p + rng.normal(0, 0.03, 3), rng.normal(0, 20, 3)
            jac = np.zeros((3, m.nv))
            mujoco.mj_jac(m, d, jac, None, tp + tR @ cop, m.body(body).id)
            np.testing.assert_allclose(leg_load_torques(side, q[idx], cop, F),
                                       (jac.T @ (tR @ F))[hanging._dadr[idx]], atol=1e-10)
