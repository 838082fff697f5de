"""The walk engine on the humanoids of example-robot-data: leg kinematics read from the
RobotModel, gait parameters scaled per robot, 20 s walks in both worlds."""

import numpy as np
import pytest

from envs import RealWorld, SimWorld, rollout
from robots import get_robot, nao_h25
from walk_engine import GaitParams, LegChain, WalkEngine, params_for
from walk_engine.footsteps import SupportPolygon

#: Measured forward speeds of θ0 over 20 s (flat ground, "none" profile) are 24.4 (G1) and 31.4 cm/s
#: (Talos) in both worlds; the floors it must clear:
MIN_SPEED = {"g1": 0.15, "talos": 0.08}


@pytest.mark.parametrize("name,analytic", [("g1", False), ("talos", True)])
def test_leg_ik_reproduces_forward_kinematics(name, analytic):
    """IK(FK(q)) = FK(q) to 1e-6 m / 1e-6 rad on random bent-knee leg poses inside the limits."""
    robot = get_robot(name)
    rng = np.random.default_rng(1)
    for side in "LR":
        leg = LegChain(robot, side)
        assert leg.analytic is analytic
        mid, half = (leg.lower + leg.upper) / 2, (leg.upper - leg.lower) / 2
        crouch = robot.pose("crouch")[robot.joint_index(leg.joint_names)]
        for _ in range(50):
            q = np.clip(crouch + rng.uniform(-0.3, 0.3, 6), mid - 0.9 * half, mid + 0.9 * half)
            p, R = leg.fk(q)
            q_ik = leg.ik(p, R, crouch)
            p2, R2 = leg.fk(q_ik)
            assert np.abs(p2 - p).max() < 1e-6 and np.abs(R2 - R).max() < 1e-6


@pytest.mark.parametrize("name", ["g1", "talos"])
def test_load_torques_are_the_jacobian_transpose(name):
    robot = get_robot(name)
    leg = LegChain(robot, "L")
    q = robot.pose("crouch")[robot.joint_index(leg.joint_names)]
    cop = leg.fk(q)[0] + np.array([0.03, -0.01, 0.0])
    F = np.array([5.0, -3.0, 300.0])
    J = leg.jacobian(q)  # sole point; a force at cop = force at the sole + moment (cop - sole) x F
    wrench = np.concatenate([F, np.cross(cop - leg.fk(q)[0], F)])
    np.testing.assert_allclose(leg.load_torques(q, cop, F), J.T @ wrench, atol=1e-9)


def test_gait_parameters_are_scaled_per_robot():
    g1, talos = params_for(get_robot("g1")), params_for(get_robot("talos"))
    assert params_for(nao_h25()) is GaitParams
    nao = GaitParams()
    for P in (g1, talos):
        th = P.initial()
        assert th.step_length > 2 * nao.step_length and th.step_period > nao.step_period  # longer legs
        assert P.length_scale > 2
        assert P.from_vector(th.to_vector()).to_dict() == pytest.approx(th.to_dict())
        with pytest.raises(ValueError, match="step_length"):
            th.replace(step_length=10.0)
    with pytest.raises(ValueError, match="robot 'nao' given for robot 'g1'"):
        WalkEngine(get_robot("g1"), GaitParams())


@pytest.mark.parametrize("name", ["g1", "talos"])
def test_support_polygon_is_the_sole_box(name):
    robot = get_robot(name)
    sp = SupportPolygon.for_robot(robot)
    assert sp.back < 0 < sp.front and sp.inner > 0 and sp.outer > 0  # the ankle lies inside its sole


@pytest.mark.parametrize("world", ["sim", "real"])
@pytest.mark.parametrize("name", ["g1", "talos"])
def test_theta0_walks_20s_without_falling(name, world):
    robot = get_robot(name)
    env = SimWorld(robot) if world == "sim" else RealWorld(robot, profile="none", terrain="flat")
    rec = rollout(env, WalkEngine(robot), seed=0, seconds=20.0)
    env.close()
    assert not rec.fell, (rec.meta["fall_reason"], rec.meta["fall_time"])
    base = rec.group("gt.base")
    speed = (base[-1, 0] - base[0, 0]) / 20.0
    assert speed >= MIN_SPEED[name], speed
