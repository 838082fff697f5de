"""Forward kinematics of the robot for drawing: link poses of a recording, frames, measured CoP.

Uses the URDF spec of the :class:`robots.RobotModel` (the kinematics both physics engines import);
quaternions are (w, x, y, z) as in recordings, rotations from :mod:`common.spatial`.
"""

from __future__ import annotations

import numpy as np

from common.spatial import quat_from_rpy, quat_rotate
from envs.recording import Recording
from robots import RobotModel
from robots.kinematics import forward_kinematics, frame_positions


def link_poses(rec: Recording) -> tuple[tuple[str, ...], np.ndarray, np.ndarray, bool]:
    """Per-link world poses of a recording: (links, pos (T, L, 3), quat wxyz (T, L, 4), grounded).

    With ground truth (``gt.base``, ``gt.quat``) the poses are exact (``grounded`` True). A log
    without it (a real robot's) is drawn upright at the origin, tilted by ``angle.roll|pitch`` when
    present, and lifted so that its lower sole touches z = 0 (``grounded`` False).
    """
    robot = rec.robot
    q = rec.group("q")
    T = len(rec)
    if rec.has("gt.base") and rec.has("gt.quat"):
        return (*forward_kinematics(robot, q, rec.group("gt.base"), rec.group("gt.quat")), True)
    if rec.has("angle"):
        ang = rec.group("angle")
        bq = quat_from_rpy(ang[:, 0], ang[:, 1])
    else:
        bq = np.tile([1.0, 0.0, 0.0, 0.0], (T, 1))
    links, pos, quat = forward_kinematics(robot, q, np.zeros((T, 3)), bq)
    low = np.minimum(frame_positions(robot, links, pos, quat, "l_sole")[:, 2],
                     frame_positions(robot, links, pos, quat, "r_sole")[:, 2])
    pos[:, :, 2] -= low[:, None]
    return links, pos, quat, False


def _measured_cop(rec: Recording, robot, links, pos, quat) -> np.ndarray:
    """(T, 3) measured CoP [m] on the ground, NaN when no foot touches: ``gt.cop``, or the
    force-weighted mean of the soles' ``cop.*`` points (from ``fsr.*``) placed by the sole poses."""
    if rec.has("gt.cop"):
        return rec.group("gt.cop")
    T = len(rec)
    if not (rec.has("fsr") and rec.has("cop")):
        return np.full((T, 3), np.nan)
    f = rec.group("fsr")
    cop = rec.group("cop")
    pl = frame_positions(robot, links, pos, quat, "l_sole")
    pr = frame_positions(robot, links, pos, quat, "r_sole")
    il, ir = links.index(robot.frames["l_sole"].link), links.index(robot.frames["r_sole"].link)
    pl = pl + quat_rotate(quat[:, il], np.column_stack([cop[:, 0], cop[:, 1], np.zeros(T)]))
    pr = pr + quat_rotate(quat[:, ir], np.column_stack([cop[:, 2], cop[:, 3], np.zeros(T)]))
    tot = f[:, 0] + f[:, 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        out = (f[:, :1] * pl + f[:, 1:] * pr) / tot[:, None]
    out[~(tot > 1e-3)] = np.nan
    return out


#: The NAO's sole box for drawing footsteps: length, width [m] (``robots.nao``), 5 mm thick, and its
#: centre ahead of / outward of the sole frame [m]; the fallback of :func:`_sole_geometry`.
_NAO_SOLE_BOX = (0.160, 0.0888, 0.005)
_NAO_SOLE_CENTER = (0.030, 0.00562)

_HEIGHTS: dict[str, float] = {}


def _root_height(robot: RobotModel) -> float:
    """Height [m] of the root link's origin above the lower sole in the ``crouch`` pose (the zero
    pose if the robot has none), base upright; cached by robot name."""
    if robot.name not in _HEIGHTS:
        q = robot.pose("crouch") if "crouch" in robot.poses else np.zeros(len(robot.joint_names))
        links, pos, quat = forward_kinematics(robot, q[None], np.zeros((1, 3)), np.array([[1.0, 0.0, 0.0, 0.0]]))
        low = min(frame_positions(robot, links, pos, quat, f)[0, 2] for f in ("l_sole", "r_sole"))
        _HEIGHTS[robot.name] = float(pos[0, 0, 2] - low)
    return _HEIGHTS[robot.name]


def _robot_scale(robot: RobotModel) -> float:
    """The robot's size relative to the NAO's (root height above the soles in the crouch; exactly
    1.0 for the NAO): scales the default camera and marker heights."""
    from robots import nao_h25  # the NAO is the reference size

    return _root_height(robot) / _root_height(nao_h25())


def _sole_geometry(robot: RobotModel) -> tuple[tuple[float, float, float], tuple[float, float]]:
    """(box (length, width, 0.005) [m], centre (ahead, outward) of the sole frame [m]) of the left
    foot's lowest collision box (the NAO's: :data:`_NAO_SOLE_BOX`, :data:`_NAO_SOLE_CENTER`); the NAO's
    values when the foot has no box."""
    fr = robot.frames["l_sole"]
    gs = robot.root_geoms if fr.link == robot.root else next(j.geoms for j in robot.joints if j.child == fr.link)
    boxes = [g for g in gs if g.kind == "box" and g.collide]
    if not boxes:
        return _NAO_SOLE_BOX, _NAO_SOLE_CENTER
    g = min(boxes, key=lambda b: b.xyz[2] - b.size[2] / 2)
    return ((float(g.size[0]), float(g.size[1]), _NAO_SOLE_BOX[2]),
            (float(g.xyz[0] - fr.offset[0]), float(g.xyz[1] - fr.offset[1])))


def _xyzw(q_wxyz: np.ndarray) -> np.ndarray:
    """Quaternions (..., 4) reordered from (w, x, y, z) to Rerun's (x, y, z, w), contiguous."""
    return np.ascontiguousarray(np.concatenate([q_wxyz[..., 1:], q_wxyz[..., :1]], axis=-1))
