"""Leg kinematics of any 6-DoF humanoid leg of a :class:`robots.RobotModel` (pure NumPy).

The NAO's legs share one HipYawPitch motor and have their own closed form
(:mod:`walk_engine.kinematics`). Every other robot's leg is read from its ``RobotModel``: the six
joints of ``groups["left_leg"]`` / ``groups["right_leg"]`` (hip to ankle, each the child of the
previous one, the first hanging from the root) and the ``l_sole`` / ``r_sole`` frame on the last link.

* Forward kinematics: the URDF chain (joint origin xyz, rpy, then the rotation about the joint axis).
* Inverse kinematics:
  - **analytic** where the leg has the classic structure hip yaw-roll-pitch with intersecting axes,
    knee pitch, ankle pitch-roll with intersecting axes, and straight thigh/shank offsets (PAL Talos):
    the closed form of Kajita et al., *Introduction to Humanoid Robotics* (Springer 2014), §2.5.4
    ("Analytical solution of inverse kinematics", eqs. 2.61-2.64);
  - **numerical** otherwise (Unitree G1: hip pitch-roll-yaw with offsets between the axes): damped
    least squares on the geometric Jacobian (Wampler 1986; Buss, "Introduction to inverse kinematics
    with Jacobian transpose, pseudoinverse and damped least squares methods", 2004, eq. 11),
    warm-started from the previous solution, iterated to 1e-10 m / 1e-10 rad.
  Both are checked against forward kinematics in the tests.
* Static load torques τ_ext = Jᵀ F of a ground force at a point of the sole.

Angles in rad, lengths in m, all in the root (torso) frame; joint vectors in leg order (6,).
"""

from __future__ import annotations

import math

import numpy as np

from robots import RobotModel
from common.spatial import axis_rotation as _axis_rot, rot_x, rot_y, rot_z
from robots.kinematics import BodyModel

#: Damping λ [-] of the least-squares step (small: the leg stays far from singular while walking;
#: large enough to keep an out-of-reach target finite).
DLS_DAMPING = 1e-4
IK_TOLERANCE = 1e-10
IK_MAX_ITER = 50


def _rpy(r, p, y) -> np.ndarray:
    """URDF ``rpy`` (fixed axes x, y, z) -> rotation matrix Rz(y) Ry(p) Rx(r)."""
    return rot_z(y) @ rot_y(p) @ rot_x(r)


_EYE6 = np.eye(6)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of (n, 3) arrays (``np.cross`` without its axis handling, which
    costs more than the product for 3-vectors)."""
    return np.stack([a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1], a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
                     a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]], axis=1)


def _jacobian(origins: np.ndarray, axes: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Geometric Jacobian (6, 6) of point ``p`` for revolute joints at ``origins`` with ``axes`` (6, 3)."""
    return np.vstack([_cross(axes, p[None] - origins).T, axes.T])


def _unit(v) -> tuple[float, float, float]:
    a = np.asarray(v, float)
    return tuple(a / np.linalg.norm(a))


class LegChain:
    """One leg of ``robot`` (``side`` "L" or "R"): FK, Jacobian, IK, load torques.

    Attributes:
        joint_names: the six joints, hip to ankle.  lower, upper: their limits [rad] (6,).
        analytic: whether :meth:`ik` uses the closed form (else damped least squares).
        hip_roll, knee, ankle_pitch, ankle_roll: indices (0-5) of those joints in the leg (by axis:
            the first x-axis joint, the last y-axis joint but one, the last y-axis joint, the last
            x-axis joint).

    Raises:
        ValueError: the leg group is not a chain of 6 hinges from the root to the sole's link, or its
            roll/pitch axes do not point along +x/+y at zero angles (the walk engine's feedback signs).
    """

    def __init__(self, robot: RobotModel, side: str):
        if side not in ("L", "R"):
            raise ValueError(f"side must be 'L' or 'R', got {side!r}")
        names = robot.groups["left_leg" if side == "L" else "right_leg"]
        spec = {j.name: j for j in robot.joints}
        chain = [spec[n] for n in names]
        sole = robot.frames["l_sole" if side == "L" else "r_sole"]
        if len(chain) != 6:
            raise ValueError(f"{robot.name} {side} leg: need 6 joints, got {len(chain)}")
        parent = robot.root
        for j in chain:
            if j.parent != parent:
                raise ValueError(f"{robot.name} {side} leg: {j.name} hangs from {j.parent}, expected {parent}")
            parent = j.child
        if sole.link != parent:
            raise ValueError(f"{robot.name} {side} leg: the sole frame is on {sole.link}, not on {parent}")
        self.joint_names = tuple(names)
        idx = robot.joint_index(names)
        self.lower, self.upper = robot.lower[idx].copy(), robot.upper[idx].copy()
        self._p = [np.array(j.xyz, float) for j in chain]
        self._R = [_rpy(*j.rpy) for j in chain]
        self._a = [np.array(_unit(j.axis)) for j in chain]
        self._sole = np.array(sole.offset, float)
        # axis of every joint at q = 0 in the root frame
        R = np.eye(3)
        world_axes = []
        for Ri, a in zip(self._R, self._a):
            R = R @ Ri
            world_axes.append(R @ a)
        x_like = [i for i, w in enumerate(world_axes) if abs(w[0]) > 0.9]
        y_like = [i for i, w in enumerate(world_axes) if abs(w[1]) > 0.9]
        if len(x_like) < 2 or len(y_like) < 2:
            raise ValueError(f"{robot.name} {side} leg: expected two roll (x) and two or more pitch (y) axes")
        self.hip_roll, self.ankle_roll, self.ankle_pitch = x_like[0], x_like[-1], y_like[-1]
        self.knee = y_like[-2]  # the pitch joint before the ankle's
        if any(world_axes[i][0] < 0 for i in x_like) or any(world_axes[i][1] < 0 for i in y_like):
            raise ValueError(f"{robot.name} {side} leg: roll axes must point along +x and pitch axes along +y")
        self.analytic = self._kajita_form()

    # ------------------------------------------------------------------ forward
    def frames(self, q) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Joint origins (6, 3), joint axes (6, 3) and the sole pose (p (3,), R (3, 3)) in the root
        frame for leg angles ``q`` (6,) [rad]."""
        p, R = np.zeros(3), np.eye(3)
        origins, axes = np.empty((6, 3)), np.empty((6, 3))
        for i, (pi, Ri, a, qi) in enumerate(zip(self._p, self._R, self._a, q)):
            p = p + R @ pi
            R = R @ Ri
            origins[i] = p
            axes[i] = R @ a
            R = R @ _axis_rot(a, float(qi))
        return origins, axes, p + R @ self._sole, R

    def fk(self, q) -> tuple[np.ndarray, np.ndarray]:
        """Sole position (3,) [m] and rotation (3, 3) in the root frame for leg angles ``q`` (6,)."""
        _, _, p, R = self.frames(q)
        return p, R

    def jacobian(self, q) -> np.ndarray:
        """Geometric Jacobian (6, 6) of the sole point (rows: linear, angular velocity; root frame)."""
        origins, axes, p, _ = self.frames(q)
        return _jacobian(origins, axes, p)

    # ------------------------------------------------------------------ inverse
    def ik(self, p_sole, R_sole, q0=None) -> np.ndarray:
        """Leg angles (6,) [rad] that put the sole frame at ``p_sole`` (3,) with rotation ``R_sole``
        (3, 3), root frame. Joint limits are not applied (the walk engine clips its targets).

        Args:
            q0: initial guess for the numerical solver (default: zeros with the knee bent 0.6 rad);
                ignored by the closed form.
        """
        p_sole = np.asarray(p_sole, float)
        R_sole = np.asarray(R_sole, float)
        if self.analytic:
            return self._ik_kajita(p_sole, R_sole)
        q = np.array(q0, float) if q0 is not None else self._default_guess()
        lam2 = DLS_DAMPING ** 2
        for _ in range(IK_MAX_ITER):
            origins, axes, p, R = self.frames(q)
            e = np.empty(6)
            e[:3] = p_sole - p
            e[3:] = 0.5 * _cross(R.T, R_sole.T).sum(0)  # orientation error (small-angle, exact at 0)
            if np.abs(e).max() < IK_TOLERANCE:
                break
            J = _jacobian(origins, axes, p)
            q = q + J.T @ np.linalg.solve(J @ J.T + lam2 * _EYE6, e)
        return q

    def _default_guess(self) -> np.ndarray:
        q = np.zeros(6)
        q[self.knee] = 0.6  # bent: keeps the solver on the knee-forward branch
        return q

    def _kajita_form(self) -> bool:
        """Hip yaw-roll-pitch on one point, knee and ankle pitch, ankle pitch-roll on one point, thigh
        and shank along -z, no origin rotations (Kajita et al. 2014, Fig. 2.19)."""
        axes = [tuple(np.round(a, 12)) for a in self._a]
        want = [(0, 0, 1), (1, 0, 0), (0, 1, 0), (0, 1, 0), (0, 1, 0), (1, 0, 0)]
        if axes != [tuple(float(v) for v in w) for w in want]:
            return False
        if any(not np.allclose(R, np.eye(3), atol=1e-12) for R in self._R):
            return False
        if np.abs(self._p[1]).max() > 1e-12 or np.abs(self._p[2]).max() > 1e-12 or np.abs(self._p[5]).max() > 1e-12:
            return False
        if np.abs(self._p[3][:2]).max() > 1e-12 or np.abs(self._p[4][:2]).max() > 1e-12:
            return False
        return bool(np.abs(self._sole[:2]).max() < 1e-12 and self._p[3][2] < 0 and self._p[4][2] < 0)

    def _ik_kajita(self, p_sole: np.ndarray, R_sole: np.ndarray) -> np.ndarray:
        """Kajita et al. 2014, §2.5.4: hip yaw q1, roll q2, pitch q3, knee q4, ankle pitch q5, roll q6."""
        A, B = -self._p[3][2], -self._p[4][2]  # thigh, shank [m]
        hip = self._p[0]
        ankle = p_sole - R_sole @ self._sole
        r = R_sole.T @ (hip - ankle)  # hip seen from the ankle, foot frame
        C = float(np.linalg.norm(r))
        C = min(max(C, abs(A - B) + 1e-9), (A + B) * (1.0 - 1e-9))  # out of reach: pulled in
        c5 = (C * C - A * A - B * B) / (2.0 * A * B)
        q4 = math.acos(max(-1.0, min(1.0, c5)))
        alpha = math.asin(max(-1.0, min(1.0, A * math.sin(math.pi - q4) / C)))
        q5 = -math.atan2(r[0], math.copysign(math.sqrt(r[1] ** 2 + r[2] ** 2), r[2])) - alpha
        q6 = math.atan2(r[1], r[2])
        q6 = q6 - math.pi if q6 > math.pi / 2 else (q6 + math.pi if q6 < -math.pi / 2 else q6)
        Rh = R_sole @ _axis_rot(np.array([1.0, 0.0, 0.0]), -q6) @ _axis_rot(np.array([0.0, 1.0, 0.0]), -(q4 + q5))
        q1 = math.atan2(-Rh[0, 1], Rh[1, 1])
        q2 = math.atan2(Rh[2, 1], -Rh[0, 1] * math.sin(q1) + Rh[1, 1] * math.cos(q1))
        q3 = math.atan2(-Rh[2, 0], Rh[2, 2])
        return np.array([q1, q2, q3, q4, q5, q6])

    # ------------------------------------------------------------------ statics
    def load_torques(self, q, cop, force) -> np.ndarray:
        """External torques (6,) [N m] on the leg's joints of a ground force ``force`` (3,) [N] at
        ``cop`` (3,) [m] (root frame): a_j · ((cop − p_j) × F), i.e. τ_ext = Jᵀ F (leg masses
        neglected); a servo must supply the negative."""
        origins, axes, _, _ = self.frames(q)
        cop, force = np.asarray(cop, float), np.asarray(force, float)
        return (axes * _cross(cop - origins, force[None])).sum(1)


def robot_geometry(robot: RobotModel) -> tuple[float, float, float, float]:
    """The geometry :func:`walk_engine.params.scaled_specs` scales the gait with: (leg length: hip
    joint to sole, legs straight [m]; stance width: distance between the soles, legs straight [m];
    whole-body CoM height above the soles in the crouch pose and with straight legs [m]; sole length
    [m]), from the robot's kinematics, inertials (torso upright) and foot collision box."""
    body = BodyModel(robot)
    legs = {s: LegChain(robot, s) for s in "LR"}
    idx = {s: robot.joint_index(legs[s].joint_names) for s in "LR"}
    crouch = robot.pose("crouch")
    straight = crouch.copy()
    for s in "LR":
        straight[idx[s]] = 0.0
    pL0, _ = legs["L"].fk(np.zeros(6))
    pR0, _ = legs["R"].fk(np.zeros(6))
    leg_length = float(legs["L"]._p[0][2] - pL0[2])
    width = float(pL0[1] - pR0[1])

    def com_above_soles(q):
        z = min(legs[s].fk(q[idx[s]])[0][2] for s in "LR")
        return float(body.com(q)[2] - z)

    foot = next(j for j in robot.joints if j.child == robot.frames["l_sole"].link)
    sole_length = max(g.size[0] for g in foot.geoms if g.kind == "box" and g.collide)
    return leg_length, width, com_above_soles(crouch), com_above_soles(straight), sole_length
