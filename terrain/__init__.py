"""Heightfield terrain (heights [m] on a grid centred at the origin) and its seeded generators."""

from terrain.heightfield import (DEFAULT_CELL, DEFAULT_SIZE, GENERATORS, MAX_AMPLITUDE, TERRAINS, Heightfield,
                                 check_amplitude, flat, fractal, from_spec, gaussian, lumpy, make, slope, steps)

__all__ = ["DEFAULT_CELL", "DEFAULT_SIZE", "GENERATORS", "MAX_AMPLITUDE", "TERRAINS", "Heightfield", "check_amplitude",
           "flat", "fractal", "from_spec", "gaussian", "lumpy", "make", "slope", "steps"]
