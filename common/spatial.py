"""Rotations and quaternions, one implementation for every package.

Quaternions are (w, x, y, z) (MuJoCo's order; PyBullet's (x, y, z, w) is converted where it is
read). Roll and pitch are the ZYX (yaw-pitch-roll) Euler angles of the torso, as a NAO's inertial
unit reports them. The vectorized functions take arrays (..., 4) / (..., 3); ``quat_to_mat``,
``cross`` and ``roll_pitch`` are scalar fast paths for the per-step observation (NumPy's general
routines cost ~10x more on 3-vectors). Conventions follow Diebel, "Representing attitude: Euler
angles, unit quaternions, and rotation vectors" (2006), eq. 125 (matrix of a quaternion) and eq. 290
(ZYX Euler angles); ``scipy.spatial.transform.Rotation`` agrees with every function here (tests).
"""

from __future__ import annotations

import math

import numpy as np


def quat_to_mat(q: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) of one unit quaternion (w, x, y, z) (a (4, N) array gives (3, 3, N))."""
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def quats_to_mats(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (n, 3, 3) of quaternions (n, 4) (w, x, y, z): :func:`quat_to_mat`'s
    arithmetic element by element, so each matrix equals it bit for bit."""
    return np.ascontiguousarray(np.moveaxis(quat_to_mat(np.asarray(q).T), -1, 0))


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product of two 3-vectors (``np.cross`` is ~10x slower on tiny arrays), or of (n, 3)
    arrays row by row (same arithmetic)."""
    if np.ndim(a) > 1 or np.ndim(b) > 1:
        a, b = np.broadcast_arrays(a, b)
        return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1], a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                         a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def libm(f, *args) -> np.ndarray:
    """``f`` (a ``math`` function) applied element by element to 1-D arrays: libm's result bit for
    bit. NumPy's SIMD ``arctan2``, ``arcsin``, ``arccos`` and ``exp`` differ from libm in the last bit
    on AVX-512 machines, so batched code that must reproduce scalar ``math`` code uses this."""
    return np.fromiter(map(f, *(np.asarray(a, dtype=float).tolist() for a in args)), float, count=len(args[0]))


def roll_pitch(R: np.ndarray):
    """Roll and pitch [rad] (ZYX Euler) of one rotation matrix (3, 3); of (n, 3, 3) matrices: two
    arrays (n,), the same ``math`` calls element by element (:func:`libm`)."""
    if np.ndim(R) > 2:
        return (libm(math.atan2, R[:, 2, 1], R[:, 2, 2]),
                libm(math.asin, np.maximum(-1.0, np.minimum(1.0, -R[:, 2, 0]))))
    return math.atan2(R[2, 1], R[2, 2]), math.asin(max(-1.0, min(1.0, -R[2, 0])))


def quat_roll_pitch(quat: np.ndarray) -> np.ndarray:
    """Roll and pitch [rad] (ZYX Euler) of unit quaternions (..., 4) (w, x, y, z) -> (..., 2)."""
    quat = np.asarray(quat, dtype=float)
    w, x, y, z = (quat[..., i] for i in range(4))
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    return np.stack([roll, pitch], axis=-1)


def quat_yaw(quat: np.ndarray) -> np.ndarray:
    """Yaw [rad] (ZYX Euler) of unit quaternions (..., 4) (w, x, y, z) -> (...)."""
    quat = np.asarray(quat, dtype=float)
    w, x, y, z = (quat[..., i] for i in range(4))
    return np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a ⊗ b of quaternions (..., 4) (w, x, y, z): the rotation b, then a."""
    aw, ax, ay, az = np.moveaxis(np.asarray(a, dtype=float), -1, 0)
    bw, bx, by, bz = np.moveaxis(np.asarray(b, dtype=float), -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz,
                     aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw], axis=-1)


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors v (..., 3) by unit quaternions q (..., 4) (w, x, y, z)."""
    w = q[..., :1]
    u = q[..., 1:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def quat_from_rpy(roll, pitch, yaw=0.0) -> np.ndarray:
    """Quaternions (..., 4) of R = Rz(yaw) Ry(pitch) Rx(roll) (ZYX Euler; URDF's ``rpy``).

    Scalars give one quaternion (4,); arrays broadcast.
    """
    r, p, y = np.broadcast_arrays(*(0.5 * np.asarray(a, dtype=float) for a in (roll, pitch, yaw)))
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.stack([cy * cp * cr + sy * sp * sr,
                     cy * cp * sr - sy * sp * cr,
                     cy * sp * cr + sy * cp * sr,
                     sy * cp * cr - cy * sp * sr], axis=-1)


__all__ = ["cross", "quat_from_rpy", "quat_mul", "quat_roll_pitch", "quat_rotate", "quat_to_mat", "quat_yaw",
           "roll_pitch"]


def rot_x(a: float) -> np.ndarray:
    """Rotation matrix (3, 3) about x by ``a`` [rad]."""
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(a: float) -> np.ndarray:
    """Rotation matrix (3, 3) about y by ``a`` [rad]."""
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(a: float) -> np.ndarray:
    """Rotation matrix (3, 3) about z by ``a`` [rad]."""
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def axis_rotation(axis: np.ndarray, a: float) -> np.ndarray:
    """Rodrigues rotation (3, 3) about the unit ``axis`` by ``a`` [rad]."""
    x, y, z = axis
    c, s = math.cos(a), math.sin(a)
    C = 1.0 - c
    return np.array([[c + x * x * C, x * y * C - z * s, x * z * C + y * s],
                     [y * x * C + z * s, c + y * y * C, y * z * C - x * s],
                     [z * x * C - y * s, z * y * C + x * s, c + z * z * C]])
