"""Shared names of the Rerun views: timelines and the colours of worlds and labels."""

from __future__ import annotations

import numpy as np

#: Timelines: ``time`` (duration [s]) and ``step`` (row index).
TIMELINE = "time"
STEP_TIMELINE = "step"
#: Base colours (RGB) per world; other labels cycle through :data:`PALETTE`.
WORLD_COLORS = {"sim": (52, 120, 246), "real": (240, 120, 30), "grounded": (40, 170, 80)}
PALETTE = [(52, 120, 246), (240, 120, 30), (40, 170, 80), (200, 50, 160), (120, 90, 200), (30, 170, 190),
           (200, 170, 20), (150, 80, 40)]


def _color(base, mix: float = 0.0) -> list[int]:
    """``base`` RGB blended towards white by ``mix`` in (0, 1], towards black by ``-mix``."""
    b = np.asarray(base, float)
    out = b + mix * (255.0 - b) if mix >= 0 else b * (1.0 + mix)
    return [int(round(v)) for v in out]


def _pick_color(world: str, used: dict[str, int]) -> tuple[int, int, int]:
    """The world's colour for its first recording (sim blue, real orange, grounded green, other
    worlds the next palette entry); later recordings of the same world step through the palette."""
    n = used.get(world, 0)
    used[world] = n + 1
    base = WORLD_COLORS.get(world, PALETTE[(len(used) - 1) % len(PALETTE)])
    return base if n == 0 else PALETTE[(PALETTE.index(base) + 3 * n) % len(PALETTE)]
