"""Swing-foot trajectory (stage 4 of :mod:`walk_engine.engine`).

Horizontal position and yaw follow a minimum-jerk (quintic) profile from the lift-off pose to the
landing pose over the single-support phase (zero velocity and acceleration at both ends, Flash &
Hogan 1985). Height rises to ``step_height`` with a minimum-jerk profile, holds it for the
``plateau`` fraction of the phase (placo's ``walk_foot_rise_ratio``, quintic-walk ``foot_z_pause``)
and comes down the same way, landing flat.
"""

from __future__ import annotations

import math


def min_jerk(s: float) -> float:
    """Minimum-jerk blend 10 s³ - 15 s⁴ + 6 s⁵ of s clipped to [0, 1] (0 -> 0, 1 -> 1)."""
    s = 0.0 if s < 0.0 else (1.0 if s > 1.0 else s)
    return s * s * s * (10.0 + s * (-15.0 + 6.0 * s))


def swing_height(s: float, step_height: float, plateau: float) -> float:
    """Swing-foot height [m] at phase s in [0, 1] of single support.

    Args:
        s: phase of the single-support phase (clipped to [0, 1]).
        step_height: apex height [m].
        plateau: fraction of the phase spent at the apex, in [0, 1).
    """
    r = (1.0 - min(max(plateau, 0.0), 0.95)) / 2.0  # rise and fall each take r of the phase
    if s <= r:
        return step_height * min_jerk(s / r)
    if s >= 1.0 - r:
        return step_height * min_jerk((1.0 - s) / r)
    return step_height


def swing_pose(p0, p1, s: float, step_height: float, plateau: float) -> tuple[float, float, float, float]:
    """Swing-foot sole pose at phase s of single support.

    Args:
        p0, p1: lift-off and landing poses (x [m], y [m], yaw [rad]).
        s: phase in [0, 1] (clipped).
        step_height, plateau: see :func:`swing_height`.

    Returns:
        (x [m], y [m], z [m] above the ground plane of the plan, yaw [rad]).
    """
    h = min_jerk(s)
    dyaw = (p1[2] - p0[2] + math.pi) % (2.0 * math.pi) - math.pi
    return (p0[0] + h * (p1[0] - p0[0]), p0[1] + h * (p1[1] - p0[1]),
            swing_height(s, step_height, plateau), p0[2] + h * dyaw)
