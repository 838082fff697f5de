"""Analytic NAO leg kinematics (forward and inverse) and a NumPy full-body CoM.

Leg chain of the NAO H25 (ros-naoqi ``nao_robot`` V50 URDF; ``robots.nao``), torso frame,
x forward, y left, z up::

    torso -> T(0, +-HIP_OFFSET_Y, -HIP_OFFSET_Z) -> HipYawPitch (axis left (0, 1/sqrt2, -1/sqrt2),
    right (0, 1/sqrt2, 1/sqrt2)) -> HipRoll (x) -> HipPitch (y) -> T(0, 0, -THIGH) -> KneePitch (y)
    -> T(0, 0, -TIBIA) -> AnklePitch (y) -> AnkleRoll (x) -> T(0, 0, -FOOT_HEIGHT) = sole

Because the HipYawPitch axis is the z axis tilted by 45 deg about x, a rotation about it is
``Rx(+45) Rz(-q) Rx(-45)`` (left) or ``Rx(-45) Rz(q) Rx(+45)`` (right); pre-multiplying the target
by ``Rx(-+45)`` turns the hip into a plain yaw-roll-pitch hip whose roll is shifted by -+45 deg.
The inverse kinematics follows the B-Human / Graf method (Graf, Härtl, Röfer, Laue, "A Robust
Closed-Loop Gait for the Standard Platform League Humanoid", Humanoids 2009 workshop; Kofinas et
al., J. Intell. Robot. Syst. 77 (2015) derive the same closed form with DH matrices): knee from the
hip-ankle distance (law of cosines, knee bent forward), ankle roll and
pitch from the hip position seen from the ankle, hip yaw/roll/pitch from the remaining rotation as
Z-X-Y Euler angles. With a *fixed* HipYawPitch (both legs share one motor; ``<mimic>`` in the V50
URDF) the leg has 5 DoF: the ankle position and the sole normal are reproduced exactly, the yaw
about the sole normal is left open (exact whenever the pose is reachable with that HipYawPitch, e.g. for
straight walking).

Angles are in rad, lengths in m. Joint vectors per leg are ordered (HipYawPitch, HipRoll,
HipPitch, KneePitch, AnklePitch, AnkleRoll). Joint limits are *not* applied here (see
:func:`clip_leg`). Everything is pure NumPy / :mod:`math`.
"""

from __future__ import annotations

import math

import numpy as np

from common.spatial import rot_x, rot_y, rot_z
from robots import RobotModel
from robots.nao import FOOT_HEIGHT, HIP_OFFSET_Y, HIP_OFFSET_Z, THIGH_LENGTH, TIBIA_LENGTH

L1 = THIGH_LENGTH
L2 = TIBIA_LENGTH
LEG_REACH = L1 + L2
#: IK targets farther than this fraction of (thigh + tibia) from the hip are pulled in.
REACH_CLIP = 0.999
#: Closest hip-ankle distance kept by the IK [m] (the knee cannot fold completely).
MIN_REACH = abs(L1 - L2) + 0.02
_C45 = math.cos(math.pi / 4)
LEG_JOINTS = ("HipYawPitch", "HipRoll", "HipPitch", "KneePitch", "AnklePitch", "AnkleRoll")


_RX_P45 = rot_x(math.pi / 4)
_RX_M45 = rot_x(-math.pi / 4)


def _side_sign(side: str) -> float:
    if side == "L":
        return 1.0
    if side == "R":
        return -1.0
    raise ValueError(f"side must be 'L' or 'R', got {side!r}")


def hip_offset(side: str) -> np.ndarray:
    """Position of the HipYawPitch joint in the torso frame [m], shape (3,)."""
    return np.array([0.0, _side_sign(side) * HIP_OFFSET_Y, -HIP_OFFSET_Z])


def leg_fk(side: str, q, frame: str = "sole") -> tuple[np.ndarray, np.ndarray]:
    """Forward kinematics of one leg in the torso frame.

    Args:
        side: ``"L"`` or ``"R"``.
        q: joint angles [rad], shape (6,): HipYawPitch, HipRoll, HipPitch, KneePitch, AnklePitch,
            AnkleRoll.
        frame: ``"sole"`` (FOOT_HEIGHT below the ankle, the ``l_sole``/``r_sole`` frame) or
            ``"ankle"`` (the ankle-roll joint).

    Returns:
        (position [m] shape (3,), rotation matrix shape (3, 3)) of the frame in the torso frame.

    Raises:
        ValueError: bad side or frame.
    """
    s = _side_sign(side)
    q0, q1, q2, q3, q4, q5 = (float(v) for v in q)
    if side == "L":
        R = _RX_P45 @ rot_z(-q0) @ rot_x(q1 - math.pi / 4)
    else:
        R = _RX_M45 @ rot_z(q0) @ rot_x(q1 + math.pi / 4)
    R = R @ rot_y(q2)
    p = np.array([0.0, s * HIP_OFFSET_Y, -HIP_OFFSET_Z])
    p = p + R @ np.array([0.0, 0.0, -L1])
    R = R @ rot_y(q3)
    p = p + R @ np.array([0.0, 0.0, -L2])
    R = R @ rot_y(q4) @ rot_x(q5)
    if frame == "sole":
        p = p + R @ np.array([0.0, 0.0, -FOOT_HEIGHT])
    elif frame != "ankle":
        raise ValueError(f"frame must be 'sole' or 'ankle', got {frame!r}")
    return p, R


def _zxy_euler(R: np.ndarray) -> tuple[float, float, float]:
    """(a, b, c) with R = Rz(a) Rx(b) Ry(c)."""
    b = math.asin(max(-1.0, min(1.0, R[2, 1])))
    a = math.atan2(-R[0, 1], R[1, 1])
    c = math.atan2(-R[2, 0], R[2, 2])
    return a, b, c


def _hip_frame_target(side: str, p_sole: np.ndarray, R_sole: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
    """Ankle target expressed in the 45-deg-rotated hip frame; position clipped to the reach.

    Returns (p', R', clipped).
    """
    p_ankle = p_sole + R_sole[:, 2] * FOOT_HEIGHT - hip_offset(side)
    M = _RX_M45 if side == "L" else _RX_P45
    p = M @ p_ankle
    d = math.sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2])
    clipped = False
    if d > REACH_CLIP * LEG_REACH:
        p = p * (REACH_CLIP * LEG_REACH / d)
        clipped = True
    elif d < MIN_REACH:
        p = (p / d * MIN_REACH) if d > 1e-12 else np.array([0.0, 0.0, -MIN_REACH])
        clipped = True
    return p, M @ R_sole, clipped


def _principal(a: float) -> float:
    """The angle a or a -+ pi that lies in [-pi/2, pi/2] (the same line through the origin)."""
    if a > math.pi / 2:
        return a - math.pi
    if a < -math.pi / 2:
        return a + math.pi
    return a


def _knee(d: float) -> float:
    c = (d * d - L1 * L1 - L2 * L2) / (2.0 * L1 * L2)
    return math.acos(max(-1.0, min(1.0, c)))


def leg_ik(side: str, p_sole, R_sole) -> np.ndarray:
    """Analytic 6-DoF leg IK (Graf et al. 2009, see the module docstring): sole pose -> joint angles.

    Args:
        side: ``"L"`` or ``"R"``.
        p_sole: desired sole-frame position in the torso frame [m], shape (3,).
        R_sole: desired sole-frame rotation in the torso frame, shape (3, 3).

    Returns:
        Joint angles [rad], shape (6,) (HipYawPitch .. AnkleRoll), knee >= 0 (bent forward).
        Targets out of reach are pulled onto the sphere of radius 0.999 (thigh + tibia) around the
        hip (never NaN); joint limits are not applied.

    Raises:
        ValueError: bad side.
    """
    p, R, _ = _hip_frame_target(side, np.asarray(p_sole, float), np.asarray(R_sole, float))
    d = math.sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2])
    q3 = _knee(d)
    # hip position seen from the ankle frame
    pa = -(R.T @ p)
    # ankle roll branch in (-pi/2, pi/2) (its limits are +-0.77 rad); wz may then be negative
    q5 = _principal(math.atan2(pa[1], pa[2]))
    wz = pa[1] * math.sin(q5) + pa[2] * math.cos(q5)
    vx = -L1 * math.sin(q3)
    vz = L1 * math.cos(q3) + L2
    q4 = math.atan2(vx, vz) - math.atan2(pa[0], wz)
    R_hip = R @ rot_x(q5).T @ rot_y(q3 + q4).T
    a, b, c = _zxy_euler(R_hip)
    if side == "L":
        return np.array([-a, b + math.pi / 4, c, q3, q4, q5])
    return np.array([a, b - math.pi / 4, c, q3, q4, q5])


def _hip_frame(sg, p, R) -> tuple:
    """Sole target in the 45-deg hip frame before the reach clip: (x, y, z, rows of R'). Plain
    arithmetic, so floats and arrays (``walk_engine.batch``) go through the same operations."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = R
    ax = p[0] + r02 * FOOT_HEIGHT
    ay = p[1] + r12 * FOOT_HEIGHT - sg * HIP_OFFSET_Y
    az = p[2] + r22 * FOOT_HEIGHT + HIP_OFFSET_Z
    c = _C45
    rows = ((r00, r01, r02),
            (c * r10 + sg * c * r20, c * r11 + sg * c * r21, c * r12 + sg * c * r22),
            (-sg * c * r10 + c * r20, -sg * c * r11 + c * r21, -sg * c * r12 + c * r22))
    return ax, c * ay + sg * c * az, -sg * c * ay + c * az, rows


def _target_scalar(side: str, p, R) -> tuple[float, float, float, tuple]:
    """Scalar version of :func:`_hip_frame_target`: (x, y, z, rows of R') in the 45-deg hip frame."""
    x, y, z, rows = _hip_frame(1.0 if side == "L" else -1.0, p, R)
    d = math.sqrt(x * x + y * y + z * z)
    if d > REACH_CLIP * LEG_REACH:
        k = REACH_CLIP * LEG_REACH / d
        x, y, z = x * k, y * k, z * k
    elif d < MIN_REACH:
        if d > 1e-12:
            k = MIN_REACH / d
            x, y, z = x * k, y * k, z * k
        else:
            x, y, z = 0.0, 0.0, -MIN_REACH
    return x, y, z, rows


def _free_hyp(side: str, p, R) -> float:
    """HipYawPitch of the unconstrained 6-DoF solution (:func:`leg_ik`), scalar fast path."""
    return _free_hyp_t(side, _target_scalar(side, p, R))


def _free_hyp_t(side: str, tgt) -> float:
    x, y, z, Rp = tgt
    pa1 = -(Rp[0][1] * x + Rp[1][1] * y + Rp[2][1] * z)
    pa2 = -(Rp[0][2] * x + Rp[1][2] * y + Rp[2][2] * z)
    q5 = _principal(math.atan2(pa1, pa2))
    c5, s5 = math.cos(q5), math.sin(q5)
    a = math.atan2(-(Rp[0][1] * c5 - Rp[0][2] * s5), Rp[1][1] * c5 - Rp[1][2] * s5)
    return -a if side == "L" else a


def _fixed_scalar(side: str, p, R, hyp: float) -> list[float]:
    return _fixed_t(side, _target_scalar(side, p, R), hyp)


def _fixed_t(side: str, tgt, hyp: float) -> list[float]:
    x, y, z, Rp = tgt
    phi = -hyp if side == "L" else hyp
    cp, sp = math.cos(phi), math.sin(phi)
    x, y = cp * x + sp * y, -sp * x + cp * y  # Rz(phi)^T p
    n0, n1, n2 = Rp[0][2], Rp[1][2], Rp[2][2]  # sole normal in the hip frame
    n0, n1 = cp * n0 + sp * n1, -sp * n0 + cp * n1
    b = _principal(math.atan2(y, -z))  # roll of the leg plane
    cb, sb = math.cos(b), math.sin(b)
    zr = -y * sb + z * cb  # Rx(b)^T p = (x, 0, zr)
    q3 = _knee(math.sqrt(x * x + zr * zr))
    q2 = math.atan2(-L2 * math.sin(q3), L1 + L2 * math.cos(q3)) - math.atan2(x, -zr)
    n1r, n2r = n1 * cb + n2 * sb, -n1 * sb + n2 * cb  # Rx(b)^T n: residual Ry(q2+q3+q4) Rx(q5) e_z
    q5 = math.atan2(-n1r, math.sqrt(n0 * n0 + n2r * n2r))
    q4 = math.atan2(n0, n2r) - q2 - q3
    return [hyp, b + math.pi / 4 if side == "L" else b - math.pi / 4, q2, q3, q4, q5]


def _as_rows(R) -> tuple:
    return tuple(tuple(r) for r in (R.tolist() if isinstance(R, np.ndarray) else R))


def leg_ik_fixed_hyp(side: str, p_sole, R_sole, hyp: float) -> np.ndarray:
    """Analytic 5-DoF leg IK with a given HipYawPitch (the fixed-HipYawPitch case of the module docstring).

    The ankle position and the sole normal (the sole frame's z axis) are met exactly; the yaw of
    the sole about its normal follows from ``hyp`` (exact when the pose is reachable with it):
    remove the fixed yaw rotation, hip roll = atan2(y, -z) of the ankle, knee by the law of
    cosines, hip pitch from the sagittal triangle, ankle pitch/roll from the sole normal.

    Args:
        side, p_sole, R_sole: as :func:`leg_ik`.
        hyp: the shared HipYawPitch angle [rad].

    Returns:
        Joint angles [rad], shape (6,), with ``q[0] == hyp``; out-of-reach targets are pulled in
        as in :func:`leg_ik` (never NaN).

    Raises:
        ValueError: bad side.
    """
    _side_sign(side)
    return np.array(_fixed_scalar(side, [float(v) for v in p_sole], _as_rows(R_sole), float(hyp)))


def legs_ik(pL, RL, pR, RR, weight_left: float = 0.5) -> tuple[np.ndarray, np.ndarray, float]:
    """Both legs with the shared HipYawPitch (one motor for both legs: ``<mimic>`` in the V50 URDF).

    Solves each leg freely (6 DoF), takes ``hyp = w * hyp_L + (1 - w) * hyp_R`` and re-solves both
    legs with it fixed (:func:`leg_ik_fixed_hyp`).

    Args:
        pL, RL, pR, RR: sole targets in the torso frame (m, shape (3,); rotation (3, 3)).
        weight_left: weight of the left leg's free HipYawPitch (support-leg weighting), in [0, 1].

    Returns:
        (q_left (6,), q_right (6,), hyp [rad]); never NaN for finite inputs.
    """
    pL = [float(v) for v in pL]
    pR = [float(v) for v in pR]
    RL, RR = _as_rows(RL), _as_rows(RR)
    hyp = weight_left * _free_hyp("L", pL, RL) + (1.0 - weight_left) * _free_hyp("R", pR, RR)
    return np.array(_fixed_scalar("L", pL, RL, hyp)), np.array(_fixed_scalar("R", pR, RR, hyp)), hyp


def leg_limits(robot: RobotModel, side: str) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper joint limits [rad] of one leg, each shape (6,), in LEG_JOINTS order."""
    idx = robot.joint_index([side + j for j in LEG_JOINTS])
    return robot.lower[idx], robot.upper[idx]


# ------------------------------------------------------------------------------ full body
def leg_load_torques(side: str, q, cop, force) -> np.ndarray:
    """Static joint torques a ground force puts on one leg (leg masses neglected).

    For each joint j with axis a_j through p_j (torso frame), the external torque about the axis
    from the force ``force`` acting on the sole at ``cop`` is ``a_j · ((cop - p_j) × force)``
    (Jacobian transpose, ``τ_ext = Jᵀ F``); a servo must supply the negative of it. Checked
    against MuJoCo's ``mj_jac`` in the tests.

    Args:
        side: ``"L"`` or ``"R"``.
        q: leg joint angles [rad], shape (6,): HipYawPitch .. AnkleRoll.
        cop: point of application [m] in the torso frame, shape (3,).
        force: ground reaction force on the foot [N] in the torso frame, shape (3,).

    Returns:
        External torques [N m] on HipYawPitch .. AnkleRoll, shape (6,).

    Raises:
        ValueError: bad side.
    """
    _side_sign(side)
    return np.array(_load_scalar(side, [float(v) for v in q], [float(v) for v in cop], [float(v) for v in force]))


def _load_scalar(side: str, q, c, F) -> list[float]:
    q0, q1, q2, q3, q4, _ = q
    sg = 1.0 if side == "L" else -1.0
    ux, uy, uz = 0.0, _C45, -sg * _C45  # HipYawPitch axis
    co, si = math.cos(q0), math.sin(q0)
    C = 1.0 - co
    # R0 = rotation about u by q0 (Rodrigues); columns
    r0 = (co + ux * ux * C, uy * ux * C + uz * si, uz * ux * C - uy * si)
    r1 = (ux * uy * C - uz * si, co + uy * uy * C, uz * uy * C + ux * si)
    r2 = (ux * uz * C + uy * si, uy * uz * C - ux * si, co + uz * uz * C)
    c1, s1 = math.cos(q1), math.sin(q1)
    ay = (r1[0] * c1 + r2[0] * s1, r1[1] * c1 + r2[1] * s1, r1[2] * c1 + r2[2] * s1)  # R1 y
    az = (-r1[0] * s1 + r2[0] * c1, -r1[1] * s1 + r2[1] * c1, -r1[2] * s1 + r2[2] * c1)  # R1 z
    ax = r0  # R1 x = R0 x
    hx, hy, hz = 0.0, sg * HIP_OFFSET_Y, -HIP_OFFSET_Z
    a2, b2 = math.sin(q2), math.cos(q2)
    kx = hx - L1 * (a2 * ax[0] + b2 * az[0])
    ky = hy - L1 * (a2 * ax[1] + b2 * az[1])
    kz = hz - L1 * (a2 * ax[2] + b2 * az[2])
    a3, b3 = math.sin(q2 + q3), math.cos(q2 + q3)
    nx = kx - L2 * (a3 * ax[0] + b3 * az[0])
    ny = ky - L2 * (a3 * ax[1] + b3 * az[1])
    nz = kz - L2 * (a3 * ax[2] + b3 * az[2])
    a4, b4 = math.sin(q2 + q3 + q4), math.cos(q2 + q3 + q4)
    ar = (b4 * ax[0] - a4 * az[0], b4 * ax[1] - a4 * az[1], b4 * ax[2] - a4 * az[2])  # ankle roll axis
    Fx, Fy, Fz = F
    cx, cy, cz = c

    def tq(a, px, py, pz):  # a . ((c - p) x F)
        dx, dy, dz = cx - px, cy - py, cz - pz
        return a[0] * (dy * Fz - dz * Fy) + a[1] * (dz * Fx - dx * Fz) + a[2] * (dx * Fy - dy * Fx)

    return [tq((ux, uy, uz), hx, hy, hz), tq(ax, hx, hy, hz), tq(ay, hx, hy, hz), tq(ay, kx, ky, kz),
            tq(ay, nx, ny, nz), tq(ar, nx, ny, nz)]
