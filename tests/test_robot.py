"""The NAO-like H25 model: one spec, one URDF, identical in both engines."""

import xml.etree.ElementTree as ET

import mujoco
import numpy as np
import pybullet
import pytest

from envs import RealWorld, SimWorld
from robots import nao_h25
from robots.nao import FOOT_HEIGHT, SOLE_CENTER_X, SOLE_CENTER_Y_OUT, SOLE_LENGTH, SOLE_WIDTH


@pytest.fixture(scope="module")
def robot():
    return nao_h25()


def test_spec_joints_groups_and_mass(robot):
    assert len(robot.joint_names) == 24
    assert len(robot.groups["head"]) == 2 and len(robot.groups["arms"]) == 10 and len(robot.groups["legs"]) == 12
    assert robot.mimic == {"RHipYawPitch": "LHipYawPitch"}
    assert len(robot.actuated_joint_names) == 23 and "RHipYawPitch" not in robot.actuated_joint_names
    assert abs(robot.total_mass - 5.305) / 5.305 < 0.01
    assert np.all(robot.lower < robot.upper) and np.all(robot.effort > 0) and np.all(robot.kp > 0)
    # right side mirrors roll limits of the left
    i, j = robot.joint_index(["LHipRoll", "RHipRoll"])
    assert robot.lower[j] == pytest.approx(-robot.upper[i]) and robot.upper[j] == pytest.approx(-robot.lower[i])
    # expand_action copies the left HipYawPitch target to the right one
    a = np.arange(23.0)
    q = robot.expand_action(a)
    li, ri = robot.joint_index(["LHipYawPitch", "RHipYawPitch"])
    assert q[li] == q[ri] and q.shape == (24,)
    with pytest.raises(KeyError, match="unknown joint"):
        robot.joint_index(["LToe"])


def test_urdf_has_documented_sole_and_mimic(robot):
    root = ET.fromstring(robot.urdf())
    assert len([j for j in root.iter("joint") if j.get("type") == "revolute"]) == 24
    rhyp = [j for j in root.iter("joint") if j.get("name") == "RHipYawPitch"][0]
    assert rhyp.find("mimic").get("joint") == "LHipYawPitch"
    for link, s in (("l_ankle", 1), ("r_ankle", -1)):
        el = [lk for lk in root.iter("link") if lk.get("name") == link][0]
        box = el.find("collision/geometry/box")
        size = [float(v) for v in box.get("size").split()]
        assert (SOLE_LENGTH, SOLE_WIDTH) == (0.160, 0.0888)
        assert size[:2] == pytest.approx([0.160, 0.0888])
        x, y, z = (float(v) for v in el.find("collision/origin").get("xyz").split())
        assert x == pytest.approx(SOLE_CENTER_X) and y == pytest.approx(s * SOLE_CENTER_Y_OUT)
        assert z - size[2] / 2 == pytest.approx(-FOOT_HEIGHT)  # bottom face 45.11 mm below the ankle
    # every link has an inertial (PyBullet would give 1 kg otherwise)
    assert all(lk.find("inertial") is not None for lk in root.iter("link"))


def test_both_engines_same_mass_and_com(robot):
    sim = SimWorld()
    real = RealWorld(profile="none", terrain="flat")
    _, info_s = sim.reset(seed=0)
    _, info_r = real.reset(seed=0)
    m_sim = float(sim.model.body_mass.sum())
    m_real = sum(real.client.getDynamicsInfo(real.body, i)[0] for i in range(-1, real.client.getNumJoints(real.body)))
    assert m_sim == pytest.approx(robot.total_mass, abs=1e-9)
    assert abs(m_sim - m_real) < 1e-6
    # same standing pose, same base placement rule: CoM within 2 mm
    assert np.linalg.norm(info_s["com"] - info_r["com"]) < 2e-3
    assert np.linalg.norm(info_s["base_pos"] - info_r["base_pos"]) < 2e-3
    # torso origin of the crouch ~0.313 m above the soles (forward kinematics of the V50 URDF lengths)
    assert info_s["base_pos"][2] == pytest.approx(0.313, abs=0.003)
    real.close()


def test_mujoco_keeps_urdf_semantics(robot):
    m = SimWorld().model
    assert m.neq == 1 and m.eq_type[0] == mujoco.mjtEq.mjEQ_JOINT  # the mimic, once
    hinges = [m.joint(i).name for i in range(m.njnt) if m.jnt_type[i] == mujoco.mjtJoint.mjJNT_HINGE]
    assert hinges == list(robot.joint_names)
    for name, eff in zip(robot.joint_names, robot.effort):
        assert m.actuator(name).forcerange[1] == pytest.approx(eff)
    assert np.all(m.dof_armature == 0)


def test_pybullet_loads_inertia_from_file(robot):
    real = RealWorld(profile="none", terrain="flat")
    real.reset(seed=0)
    p, b = real.client, real.body
    names = {p.getJointInfo(b, i)[12].decode(): i for i in range(p.getNumJoints(b))}
    thigh = p.getDynamicsInfo(b, names["LThigh"])
    assert thigh[0] == pytest.approx(0.38968)
    # principal inertia of the URDF tensor (not one recomputed from the capsule)
    spec = [j for j in robot.joints if j.child == "LThigh"][0].inertial.inertia
    ixx, iyy, izz, ixy, ixz, iyz = spec
    ev = np.linalg.eigvalsh(np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]]))
    assert sorted(thigh[2]) == pytest.approx(sorted(ev), rel=1e-4)
    assert p.getJointInfo(b, names["LThigh"])[2] == pybullet.JOINT_REVOLUTE
    real.close()
