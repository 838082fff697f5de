"""Value lists on the command line: ``start:stop:count`` ranges, comma lists, single numbers."""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

HINT = "expected 'start:stop:count' (e.g. 0:0.04:9), a comma list (e.g. 0,0.01,0.02) or one number"


def parse_values(spec: str | float | Sequence[float], what: str, hint: str = HINT) -> list[float]:
    """Parse a value list: ``start:stop:count`` (``numpy.linspace``, both ends included), a comma
    list, a single number, or a sequence of numbers.

    Args:
        spec: the text (or number, or numbers) to parse.
        what: the flag it came from, for the error message (e.g. ``"--amplitude"``).
        hint: what a well-formed value looks like, for the error message.

    Returns:
        the values rounded to 12 decimals (so 0:0.04:9 gives 0.005, not 0.005000000000000001),
        in the order given, duplicates removed.

    Raises:
        ValueError: malformed text, a count < 1 or equal ends (an empty range), a non-finite value;
            the message names ``what``.
    """
    if isinstance(spec, (int, float)):
        values = [float(spec)]
    elif isinstance(spec, str):
        text = spec.strip()

        def num(s: str) -> float:
            try:
                return float(s)
            except ValueError:
                raise ValueError(f"{what}: malformed value {spec!r}; {hint}") from None

        if ":" in text:
            parts = text.split(":")
            if len(parts) != 3:
                raise ValueError(f"{what}: malformed range {spec!r}; {hint}")
            start, stop, count = num(parts[0]), num(parts[1]), num(parts[2])
            if not count.is_integer() or count < 1:
                raise ValueError(f"{what}: empty range {spec!r}: the count must be a positive integer, "
                                 f"got {parts[2]!r}")
            if count > 1 and start == stop:
                raise ValueError(f"{what}: empty range {spec!r}: start equals stop")
            values = np.linspace(start, stop, int(count)).tolist()
        else:
            if text and any(not v.strip() for v in text.split(",")):
                raise ValueError(f"{what}: malformed list {spec!r} (an empty item); {hint}")
            values = [num(v) for v in text.split(",") if v.strip()]
    else:
        values = [float(v) for v in spec]
    if not values:
        raise ValueError(f"{what}: no values in {spec!r}; {hint}")
    for v in values:
        if not math.isfinite(v):
            raise ValueError(f"{what}: {v} is not a finite number (from {spec!r})")
    out: list[float] = []
    for v in values:
        v = round(v, 12) + 0.0  # + 0.0 turns -0.0 into 0.0
        if v not in out:
            out.append(v)
    return out


__all__ = ["parse_values"]
