"""Seed derivation: every random draw of a run comes from its seed and the purpose of the draw.

``derive_seeds(root, purpose, *keys, n=n)`` gives ``n`` 32-bit seeds from
``numpy.random.SeedSequence([root, purpose, *keys])`` (``generate_state``): the same seeds on every
machine and executor, independent streams for different purposes or keys, and prefix-stable in ``n``
(the first k of n are the k asked for with ``n=k``), so a run resumed with more episodes or trials
adds to those it has. Each experiment names its purposes as constants beside its config.
"""

from __future__ import annotations

import numpy as np


def derive_seeds(*keys: int, n: int) -> list[int]:
    """``n`` seeds keyed by ``keys`` (root seed, purpose, then any indices).

    Raises:
        ValueError: a negative key or ``n`` < 0 (``numpy.random.SeedSequence`` takes non-negative integers).
    """
    if n < 0 or any(int(k) < 0 for k in keys):
        raise ValueError(f"seeds need non-negative keys and count, got {keys}, n={n}")
    return [int(s) for s in np.random.SeedSequence([int(k) for k in keys]).generate_state(n, dtype=np.uint32)]


def derive_seed(*keys: int) -> int:
    """The first of :func:`derive_seeds` ``(*keys, n=1)``."""
    return derive_seeds(*keys, n=1)[0]


__all__ = ["derive_seed", "derive_seeds"]
