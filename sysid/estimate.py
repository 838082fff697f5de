"""Floating-base state from what a robot measures (joint angles, torso roll/pitch, gyro, foot forces),
for windowed replay of logs without ground truth.

Assumptions (flat ground at z = 0, the stance foot does not slip): orientation from the logged
torso roll/pitch (yaw 0: on flat ground yaw does not change the dynamics), angular velocity from
the gyro, height such that the lowest sole corner touches the ground, linear velocity such that
the stance sole (larger FSR force) is at rest. Source: standard leg-odometry estimators
(e.g. Bloesch et al., "State estimation for legged robots", RSS 2012), reduced to one sample.
"""

from __future__ import annotations

import functools

import mujoco
import numpy as np

from common.spatial import quat_from_rpy
from sysid.data import Log


@functools.lru_cache(maxsize=4)
def _kin_model(physics_dt: float, robot_name: str = "nao"):
    from sysid.model import Structure, replay_model

    rm = replay_model(Structure(fixed_base=False, physics_dt=physics_dt, robot=robot_name))
    return rm, mujoco.MjData(rm.model)


def base_state(log: Log, k: int) -> dict:
    """Estimated torso ``pos``, ``quat`` (wxyz), ``linvel``, ``angvel`` (world) at row ``k``.

    Raises:
        ValueError: the log lacks ``angle`` or ``gyro`` columns (needed for a floating base).
    """
    if "angle" not in log.imu or "gyro" not in log.imu:
        raise ValueError(f"{log.name}: a floating-base log needs angle.* and gyro.* columns (or gt.* ground truth, "
                         "used with --use-ground-truth) to restart replays from the measured state")
    rm, d = _kin_model(log.physics_dt, log.robot_name)
    m = rm.model
    roll, pitch = log.imu["angle"][k]
    quat = quat_from_rpy(float(roll), float(pitch))
    mujoco.mj_resetData(m, d)
    d.qpos[3:7] = quat
    d.qpos[rm.qadr] = log.q[k]
    mujoco.mj_kinematics(m, d)
    R = d.xmat[m.body(rm.robot.root).id].reshape(3, 3)
    low = min(float(d.site_xpos[m.site(s).id][2]) for s in ("l_sole", "r_sole"))
    pos = np.array([0.0, 0.0, -low + 0.0005])
    w_world = R @ log.imu["gyro"][k]
    d.qpos[0:3] = pos
    d.qvel[3:6] = log.imu["gyro"][k]  # free-joint angular velocity is in the body frame
    if log.dq is not None:
        d.qvel[rm.dadr] = log.dq[k]
    mujoco.mj_forward(m, d)
    stance = "l_sole" if log.fsr is None or log.fsr[k, 0] >= log.fsr[k, 1] else "r_sole"
    v6 = np.zeros(6)
    mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_SITE, m.site(stance).id, v6, 0)
    return {"pos": pos, "quat": quat, "linvel": -v6[3:], "angvel": w_world}
