"""Forward kinematics of a robot model: link poses and the whole-body centre of mass.

One chain, the URDF spec of :class:`robots.RobotModel` (joint origins ``xyz`` [m] and ``rpy`` [rad],
hinge ``axis`` in the joint frame; the kinematics both physics engines import): child pose = parent
pose * translation(xyz) * rotation(rpy) * rotation(axis, q). Two evaluations of it: :class:`BodyModel`
for one pose in the root frame with rotation matrices (the walk engine places the torso with its
CoM), :func:`forward_kinematics` for T poses in the world with quaternions (w, x, y, z) (drawing
recordings).
"""

from __future__ import annotations

import numpy as np

from common.spatial import axis_rotation, quat_from_rpy, quat_mul, quat_rotate, rot_x, rot_y, rot_z
from robots.model import RobotModel


class BodyModel:
    """Full-body forward kinematics and centre of mass of a :class:`robots.RobotModel` (NumPy).

    Args:
        robot: the robot; its joints must be listed parents-first (URDF order, as ``nao``).

    Used to place the torso so that the *whole-body* CoM (not only a point mass) sits where the
    LIPM plan wants it (stage 5 of :mod:`walk_engine.engine`).
    """

    def __init__(self, robot: RobotModel):
        self.robot = robot
        self.total_mass = robot.total_mass
        self._joints = []
        self._rpy = {}
        for j in robot.joints:
            ax = np.array(j.axis, float)
            self._joints.append((j.parent, j.child, np.array(j.xyz, float), ax / np.linalg.norm(ax),
                                 j.inertial.mass, np.array(j.inertial.com, float)))
            if any(j.rpy):  # joint origins rotated (URDFs of example-robot-data; the NAO has none)
                self._rpy[j.child] = rot_z(j.rpy[2]) @ rot_y(j.rpy[1]) @ rot_x(j.rpy[0])
        self._root = robot.root
        self._root_mass = robot.root_inertial.mass
        self._root_com = np.array(robot.root_inertial.com, float)

    def com(self, q: np.ndarray) -> np.ndarray:
        """Whole-body CoM [m] in the torso frame for joint angles ``q`` [rad], shape (n joints,)
        (``robot.joint_names`` order). Returns shape (3,)."""
        frames = {self._root: (np.zeros(3), np.eye(3))}
        acc = self._root_mass * self._root_com
        for (parent, child, xyz, axis, mass, com), a in zip(self._joints, q):
            p0, R0 = frames[parent]
            p = p0 + R0 @ xyz
            if child in self._rpy:
                R0 = R0 @ self._rpy[child]
            R = R0 @ axis_rotation(axis, float(a))
            frames[child] = (p, R)
            acc = acc + mass * (p + R @ com)
        return acc / self.total_mass


def forward_kinematics(robot: RobotModel, q: np.ndarray, base_pos: np.ndarray, base_quat: np.ndarray
                       ) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    """World poses of all links from joint angles and the floating-base pose.

    Uses the URDF spec of ``robot`` (joint origins ``xyz`` [m] and ``rpy`` [rad], hinge ``axis`` in
    the joint frame), the same kinematics both physics engines import: child pose = parent pose
    * translation(xyz) * rotation(rpy) * rotation(axis, q).

    Args:
        robot: the model; its joints must list parents before children.
        q: joint angles [rad], shape (T, n) in ``robot.joint_names`` order (n = 24 for the NAO).
        base_pos: root link origin (the NAO's torso, the G1's pelvis) in the world [m], shape (T, 3).
        base_quat: root orientation, unit quaternions (w, x, y, z), shape (T, 4).

    Returns:
        (links, pos, quat): link names (``robot.links`` order, root first), positions (T, L, 3) [m]
        and orientations (T, L, 4) as quaternions (w, x, y, z).

    Raises:
        ValueError: shapes that do not match.
    """
    q = np.asarray(q, dtype=float)
    base_pos = np.asarray(base_pos, dtype=float)
    base_quat = np.asarray(base_quat, dtype=float)
    n = len(robot.joint_names)
    if q.ndim != 2 or q.shape[1] != n:
        raise ValueError(f"q must have shape (T, {n}), got {q.shape}")
    T = q.shape[0]
    if base_pos.shape != (T, 3) or base_quat.shape != (T, 4):
        raise ValueError(f"base_pos/base_quat must have shapes ({T}, 3)/({T}, 4), got {base_pos.shape}/{base_quat.shape}")
    links = robot.links
    index = {name: i for i, name in enumerate(links)}
    pos = np.empty((T, len(links), 3))
    quat = np.empty((T, len(links), 4))
    pos[:, 0] = base_pos
    quat[:, 0] = base_quat / np.linalg.norm(base_quat, axis=1, keepdims=True)
    for k, j in enumerate(robot.joints):
        ip, ic = index[j.parent], index[j.child]
        qp = quat[:, ip]
        pos[:, ic] = pos[:, ip] + quat_rotate(qp, np.broadcast_to(np.asarray(j.xyz, float), (T, 3)))
        if any(j.rpy):  # joint origin rotation (URDF ``<origin rpy>``); the NAO has none
            qp = quat_mul(qp, quat_from_rpy(*j.rpy))
        axis = np.asarray(j.axis, float)
        axis = axis / np.linalg.norm(axis)
        half = 0.5 * q[:, k]
        qj = np.concatenate([np.cos(half)[:, None], np.sin(half)[:, None] * axis], axis=1)
        quat[:, ic] = quat_mul(qp, qj)
    return links, pos, quat


def frame_positions(robot: RobotModel, links: tuple[str, ...], pos: np.ndarray, quat: np.ndarray,
                    frame: str, offset=(0.0, 0.0, 0.0)) -> np.ndarray:
    """World position (T, 3) [m] of point ``offset`` [m] given in robot frame ``frame`` (e.g.
    ``l_sole``), from the link poses of :func:`forward_kinematics`."""
    fr = robot.frames[frame]
    i = links.index(fr.link)
    local = np.asarray(fr.offset, float) + np.asarray(offset, float)
    return pos[:, i] + quat_rotate(quat[:, i], np.broadcast_to(local, pos[:, i].shape))


__all__ = ["BodyModel", "forward_kinematics", "frame_positions"]
