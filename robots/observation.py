"""The observation vector of a humanoid and the recording columns named after it: one layout, derived
from the robot model, that the worlds (``envs``), the walk engine, the recordings and the grounding
read.

The observation is what the robot measures, a flat float64 vector of fields: ``q`` encoder angles
[rad] and ``dq`` joint velocities [rad/s] (one per joint, in ``RobotModel.joint_names`` order),
``gyro`` torso angular velocity in the torso frame [rad/s] (3), ``acc`` accelerometer specific force
in the torso frame [m/s^2] (3), ``angle`` torso roll and pitch [rad] (2), ``fsr`` total normal force
under the left/right foot [N] (2), ``cop`` centre of pressure of each foot in its sole frame [m] (4).
Its entries are named like the recording columns: ``q.LKneePitch``, ``gyro.x``, ``cop.Ly``; commands
and applied targets are ``cmd.<joint>`` and ``app.<joint>`` for the actuated joints.
"""

from __future__ import annotations

import numpy as np

from robots.model import RobotModel

#: The fields of the observation with the names of their entries (None: one per joint).
FIELDS: dict[str, tuple[str, ...] | None] = {
    "q": None, "dq": None, "gyro": ("x", "y", "z"), "acc": ("x", "y", "z"), "angle": ("roll", "pitch"),
    "fsr": ("L", "R"), "cop": ("Lx", "Ly", "Rx", "Ry"),
}


class ObservationLayout:
    """Names and slices of a robot's observation vector (module docstring).

    Attributes:
        sizes: field -> number of entries; slices: field -> slice into the vector; size: its length;
        names: the column name of every entry, in order.
    """

    def __init__(self, robot: RobotModel):
        self.robot = robot
        self.sizes: dict[str, int] = {}
        self.slices: dict[str, slice] = {}
        self.names: list[str] = []
        for f, entries in FIELDS.items():
            entries = robot.joint_names if entries is None else entries
            self.slices[f] = slice(len(self.names), len(self.names) + len(entries))
            self.sizes[f] = len(entries)
            self.names += [f"{f}.{e}" for e in entries]
        self.size = len(self.names)

    def split(self, obs: np.ndarray) -> dict[str, np.ndarray]:
        """Field name -> view of ``obs`` (works on (..., size) arrays)."""
        return {k: obs[..., s] for k, s in self.slices.items()}

    def __getitem__(self, key: str) -> slice:
        return self.slices[key]

    def columns(self, group: str, joints=None) -> tuple[str, ...]:
        """Column names of a joint group: ``q``/``dq`` (every joint, or ``joints``), ``cmd``/``app``
        (the actuated joints' commands and applied targets, or ``joints``).

        Raises:
            KeyError: an unknown group.
        """
        if group not in ("q", "dq", "cmd", "app"):
            raise KeyError(f"unknown joint column group {group!r}; choose q, dq, cmd or app")
        if joints is None:
            joints = self.robot.joint_names if group in ("q", "dq") else self.robot.actuated_joint_names
        return tuple(f"{group}.{j}" for j in joints)


__all__ = ["FIELDS", "ObservationLayout"]
