"""Test helper: the sensor noise of the project's stepping-log tests (1 mrad encoders, 2 mrad torso
angle, 0.01 rad/s gyro), added in place to a recording's columns."""

import numpy as np


def add_sensor_noise(rec, seed: int) -> None:
    """Add white noise to ``rec``'s ``q.*``, ``angle.*`` and ``gyro.*`` columns (in place), from ``seed``."""
    rng = np.random.default_rng(seed)
    for c in rec.columns:
        sd = 1e-3 if c.startswith("q.") else 2e-3 if c.startswith("angle.") else 1e-2 if c.startswith("gyro.") else 0
        if sd:
            rec.columns[c] = rec.columns[c] + rng.normal(0, sd, len(rec))
