"""Humanoids from example-robot-data (Unitree G1, PAL Talos) in both worlds."""

import os
import xml.etree.ElementTree as ET

import numpy as np
import pybullet
import pytest
from pybullet_utils import bullet_client

from envs import CommandLog, HoldPose, RealWorld, SimWorld, rollout
from envs.excitation import chirp_with_holds
from robots import ROBOT_NAMES, get_robot
from robots.urdf_robots import G1, SPECS, robots_dir

JOINTS = {"g1": 29, "talos": 32}


def _urdf_mass(spec) -> float:
    root = ET.parse(os.path.join(robots_dir(), spec.urdf)).getroot()
    return sum(float(ln.find("inertial/mass").get("value")) for ln in root.findall("link")
               if ln.find("inertial") is not None)


def _bullet_mass(urdf_path: str) -> float:
    p = bullet_client.BulletClient(connection_mode=pybullet.DIRECT)
    try:
        b = p.loadURDF(urdf_path, flags=pybullet.URDF_USE_INERTIA_FROM_FILE)
        return sum(p.getDynamicsInfo(b, i)[0] for i in range(-1, p.getNumJoints(b)))
    finally:
        p.disconnect()


@pytest.mark.parametrize("name", ["g1", "talos"])
def test_same_robot_in_both_engines(name):
    """Joint count and total mass agree between the URDF's inertials, MuJoCo and PyBullet."""
    robot = get_robot(name)
    assert len(robot.joint_names) == JOINTS[name]
    assert robot.total_mass == pytest.approx(_urdf_mass(SPECS[name]), rel=1e-9)
    sim = SimWorld(robot)
    assert sim.model.nu == JOINTS[name]
    assert sim.model.body_mass.sum() == pytest.approx(robot.total_mass, rel=1e-9)
    real = RealWorld(robot, profile="none")
    real.reset(seed=0)
    assert len(real._jidx) == JOINTS[name]
    assert real._masses.sum() == pytest.approx(robot.total_mass, rel=1e-9)
    real.close()


def test_massless_links_add_nothing_in_pybullet():
    """The trap the merge avoids: PyBullet gives the raw G1 URDF's four links without <inertial>
    1 kg each; the merged model carries exactly the URDF's inertial masses."""
    raw = _bullet_mass(os.path.join(robots_dir(), G1.urdf))
    assert raw == pytest.approx(_urdf_mass(G1) + 4.0, abs=1e-6)
    assert _bullet_mass(get_robot("g1").write_urdf()) == pytest.approx(_urdf_mass(G1), rel=1e-9)


@pytest.mark.parametrize("name", ["g1", "talos"])
def test_feet_are_the_only_contact_boxes_and_soles_sit_below_the_ankle_on_their_bottom(name):
    robot = get_robot(name)
    env = SimWorld(robot)
    m, d = env.model, env.data
    env.reset(seed=0)
    robot_geoms = [g for g in range(m.ngeom) if g != m.geom("ground").id]
    assert len(robot_geoms) == 2 and all(m.geom_type[g] == 6 for g in robot_geoms)  # mjGEOM_BOX
    for g in robot_geoms:
        body = m.body(m.geom_bodyid[g]).name
        sole = "l_sole" if body == robot.frames["l_sole"].link else "r_sole"
        assert body == robot.frames[sole].link
        R = d.geom_xmat[g].reshape(3, 3)
        local = R.T @ (d.site_xpos[m.site(sole).id] - d.geom_xpos[g])  # the sole point in the box frame
        assert local[2] == pytest.approx(-m.geom_size[g][2], abs=1e-9)  # on the bottom face
        assert np.all(np.abs(local[:2]) < m.geom_size[g][:2])  # inside it
        b = m.geom_bodyid[g]  # straight below the ankle (the foot origin): x = y = 0 in the foot frame
        in_foot = d.xmat[b].reshape(3, 3).T @ (d.site_xpos[m.site(sole).id] - d.xpos[b])
        np.testing.assert_allclose(in_foot[:2], 0.0, atol=1e-12)


@pytest.mark.parametrize("world", ["sim", "real"])
@pytest.mark.parametrize("name", ["g1", "talos"])
def test_crouch_stands_5s(name, world):
    robot = get_robot(name)
    env = SimWorld(robot) if world == "sim" else RealWorld(robot, profile="none")
    rec = rollout(env, HoldPose(robot, "crouch"), seed=0, seconds=5.0)
    assert not rec.fell, rec.meta["fall_reason"]
    assert rec.meta["robot"] == name
    com = rec.group("gt.com")
    assert np.linalg.norm(com[-1, :2] - com[0, :2]) < 0.03
    fsr = rec.group("fsr")[-100:].mean(0)
    assert fsr.sum() == pytest.approx(robot.total_mass * 9.81, rel=0.05)
    assert fsr.min() > 0.3 * robot.total_mass * 9.81  # both feet carry it
    env.close()


@pytest.mark.parametrize("name", ["g1", "talos"])
def test_fixed_base_leg_chirp_agrees_across_engines(name):
    """Same URDF, same PD, same 1 ms step: a 6 s leg chirp (0.3-4 Hz, 0.15 rad, kept 0.1 rad inside
    the limits) replays within 3 mrad RMS per joint in MuJoCo and PyBullet."""
    robot = get_robot(name)
    cmd = chirp_with_holds(robot, seconds=6.0, amplitude=0.15, margin=0.1, joints=robot.groups["legs"])
    q_sim = rollout(SimWorld(robot, fixed_base=True), CommandLog(cmd), seed=0, seconds=6.0).group("q")
    real = RealWorld(robot, fixed_base=True, profile="none")
    q_real = rollout(real, CommandLog(cmd), seed=0, seconds=6.0).group("q")
    real.close()
    assert q_sim.shape == q_real.shape == (600, JOINTS[name])
    assert np.all(np.ptp(q_sim, axis=0)[robot.joint_index(robot.groups["legs"])] > 0.1)
    rms = np.sqrt(((q_sim - q_real) ** 2).mean(0))
    assert rms.max() <= 3e-3, dict(zip(robot.joint_names, np.round(rms * 1e3, 3)))


def test_get_robot_names():
    assert ROBOT_NAMES[0] == "nao" and get_robot("nao") is get_robot("nao")
    with pytest.raises(KeyError, match="unknown robot 'asimo'"):
        get_robot("asimo")
