"""Command logs that excite the joints: used for engine-agreement tests and actuator replays."""

from __future__ import annotations

import numpy as np

from common.defaults import CONTROL_DT
from robots import RobotModel


def chirp_with_holds(robot: RobotModel, seconds: float = 6.0, f0: float = 0.3, f1: float = 4.0,
                     amplitude: float = 0.25, hold: float = 1.0, pose: str = "crouch",
                     control_dt: float = CONTROL_DT, joints: list[str] | None = None,
                     margin: float = 0.01) -> np.ndarray:
    """Joint targets [rad], shape (round(seconds / control_dt), 23): hold ``pose`` for ``hold``
    seconds, a linear chirp from ``f0`` to ``f1`` Hz of ``amplitude`` rad around the pose, then hold
    again for the last ``hold`` seconds.

    Each actuated joint gets the chirp scaled by ``cos(phi_j)`` with phases spread over [0, pi]
    (joints move with different amplitudes and signs, so the replay is not a symmetric motion);
    ``joints`` restricts the motion to the named joints. Targets are kept 0.01 rad inside the
    joint limits by default (``margin`` [rad]; PD overshoot can still touch a limit, where the two
    engines' limit constraints differ).

    Raises:
        ValueError: ``seconds <= 2 * hold`` or non-positive frequencies/amplitude.
    """
    if seconds <= 2 * hold or f0 <= 0 or f1 <= 0 or amplitude < 0:
        raise ValueError("need seconds > 2 * hold, positive frequencies and amplitude >= 0")
    n = int(round(seconds / control_dt))
    t = np.arange(n) * control_dt
    T = seconds - 2 * hold
    tt = t - hold
    phase = 2 * np.pi * (f0 * tt + (f1 - f0) / (2 * T) * tt**2)
    s = np.where((t >= hold) & (t < hold + T), np.sin(phase), 0.0)
    q0 = robot.pose(pose, actuated=True)
    w = np.cos(np.linspace(0.0, np.pi, len(q0)))
    if joints is not None:
        mask = np.isin(robot.actuated_joint_names, joints)
        w = np.where(mask, w, 0.0)
    lo = robot.lower[robot.actuated_index] + margin
    hi = robot.upper[robot.actuated_index] - margin
    return np.clip(q0[None] + amplitude * s[:, None] * w[None], lo, hi)
