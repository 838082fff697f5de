"""Uneven ground of the strangers' world: fractal Perlin gradient noise of a given RMS height.

The surface is fractional Brownian motion built from gradient noise: ``octaves`` layers of 2-D
Perlin noise (random unit gradients on a square lattice, quintic fade ``6t^5 - 15t^4 + 10t^3``:
K. Perlin, "Improving Noise", SIGGRAPH 2002), the layer ``o`` of wavelength ``wavelength / 2^o`` and
amplitude ``0.5^o`` (lacunarity 2, persistence 0.5: F. K. Musgrave, "Fractal solid textures", in
Ebert et al., *Texturing & Modeling: A Procedural Approach*, 3rd ed., 2003), each layer's lattice
shifted by a random offset. The sum is made zero-mean and scaled to the RMS height ``rms_height``
(Sq, ISO 25178-2) over the whole field, then an optional flat start pad of radius ``start_radius``
is blended in (the default 0: the robot stands on the uneven ground from the start).

This is not the project's ``terrain.lumpy`` (sparse Gaussian bumps) nor ``terrain.gaussian`` (a
Gaussian-smoothed white-noise field, the diagnosis's ground model): its spectrum is a band-limited
power law with lattice-scale gradient structure.
"""

from __future__ import annotations

import math

import numpy as np

from terrain import Heightfield

#: Field size [m] (x, y) and grid spacing [m]: 2 cm cells keep the finest layer (>= 5 cm) at >= 2.5 cells.
SIZE = (6.0, 3.0)
CELL = 0.02
OCTAVES = 3
PERSISTENCE = 0.5
LACUNARITY = 2.0


def _fade(t: np.ndarray) -> np.ndarray:
    return t * t * t * (t * (t * 6.0 - 15.0) + 10.0)


def perlin_layer(rng: np.random.Generator, X: np.ndarray, Y: np.ndarray, wavelength: float) -> np.ndarray:
    """One layer of 2-D Perlin gradient noise at the points (X, Y) [m] (same shape), lattice spacing
    ``wavelength`` [m]; values in about [-0.7, 0.7] (dimensionless). Draws the lattice offset (2) and
    one gradient angle per lattice node from ``rng``."""
    off = rng.uniform(0.0, wavelength, 2)
    u = (X - X.min() + off[0]) / wavelength
    v = (Y - Y.min() + off[1]) / wavelength
    nx, ny = int(math.floor(u.max())) + 2, int(math.floor(v.max())) + 2
    ang = rng.uniform(0.0, 2.0 * math.pi, (ny, nx))
    gx, gy = np.cos(ang), np.sin(ang)
    i, j = np.floor(u).astype(int), np.floor(v).astype(int)
    fu, fv = u - i, v - j

    def corner(di: int, dj: int) -> np.ndarray:
        return gx[j + dj, i + di] * (fu - di) + gy[j + dj, i + di] * (fv - dj)

    su, sv = _fade(fu), _fade(fv)
    bottom = corner(0, 0) + su * (corner(1, 0) - corner(0, 0))
    top = corner(0, 1) + su * (corner(1, 1) - corner(0, 1))
    return bottom + sv * (top - bottom)


def perlin_ground(rng: np.random.Generator, rms_height: float, wavelength: float = 0.3, *, size=SIZE,
                  cell_size: float = CELL, octaves: int = OCTAVES, start_radius: float = 0.0) -> Heightfield:
    """A fractal Perlin heightfield (module docstring) centred at the origin.

    Args:
        rng: the stream the lattices are drawn from (one episode's terrain stream).
        rms_height: Sq [m] of the field before the start pad (>= 0).
        wavelength: lattice spacing of the coarsest layer [m] (> 2 cells).
        size: (x, y) extent [m]; cell_size: grid spacing [m].
        octaves: layers (>= 1); the finest has wavelength ``wavelength / 2^(octaves-1)``.
        start_radius: radius [m] of a flat pad around the origin (0: none), blended over 0.15 m.

    Returns:
        A :class:`terrain.Heightfield` (heights (ny, nx) [m]; ``spec`` None: not a ``terrain`` generator).

    Raises:
        ValueError: a negative RMS height, a wavelength whose finest layer spans fewer than two cells,
            octaves < 1, a non-positive size or cell, or a negative pad radius.
    """
    if not (np.isfinite(rms_height) and rms_height >= 0):
        raise ValueError(f"rms_height must be a finite number >= 0 m, got {rms_height!r}")
    if int(octaves) != octaves or octaves < 1:
        raise ValueError(f"octaves must be an integer >= 1, got {octaves!r}")
    if not (cell_size > 0 and size[0] > 0 and size[1] > 0):
        raise ValueError(f"size and cell_size must be positive, got size={size}, cell_size={cell_size}")
    finest = wavelength / LACUNARITY ** (octaves - 1)
    if not (np.isfinite(wavelength) and finest >= 2.0 * cell_size):
        raise ValueError(f"wavelength {wavelength!r} m gives a finest layer of {finest:.3g} m, under two cells "
                         f"({2 * cell_size:g} m)")
    if start_radius < 0:
        raise ValueError(f"start_radius must be >= 0 m, got {start_radius}")
    nx, ny = int(np.rint(size[0] / cell_size)) + 1, int(np.rint(size[1] / cell_size)) + 1
    x = (np.arange(nx) - (nx - 1) / 2.0) * cell_size
    y = (np.arange(ny) - (ny - 1) / 2.0) * cell_size
    X, Y = np.meshgrid(x, y)
    h = np.zeros_like(X)
    for o in range(int(octaves)):
        h += PERSISTENCE ** o * perlin_layer(rng, X, Y, wavelength / LACUNARITY ** o)
    h -= h.mean()
    sd = h.std()
    h = h * (rms_height / sd) if sd > 0 else np.zeros_like(h)
    if start_radius > 0:
        t = np.clip((np.hypot(X, Y) - start_radius) / 0.15, 0.0, 1.0)
        h *= t * t * (3.0 - 2.0 * t)
    return Heightfield(h, cell_size, f"perlin(sq={rms_height:g},wl={wavelength:g})")


def episode_ground(seed: int | None, rms_height: float, wavelength: float) -> Heightfield:
    """The ground of one episode: :func:`perlin_ground` drawn from the episode seed's terrain stream
    (the second of three streams spawned from ``numpy.random.SeedSequence(seed)``, as the project's
    real world does; None counts as seed 0), so a seed fixes the field."""
    ss = np.random.SeedSequence(0 if seed is None else int(seed)).spawn(3)[1]
    return perlin_ground(np.random.default_rng(ss), rms_height, wavelength)
