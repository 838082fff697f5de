"""Heightfield terrain shared by both engines, and its seeded generators.

A :class:`Heightfield` is a grid of heights ``heights[iy, ix]`` [m] (row index = y, column
index = x) with square cells of ``cell_size`` [m], centred on the world origin: node (iy, ix)
sits at ``x = -half_x + ix * cell_size``, ``y = -half_y + iy * cell_size``.

Between nodes the surface is the triangulation MuJoCo uses: each cell is split along its
(x0, y0)-(x1, y1) diagonal (this project's measurement, ``tests/test_terrain.py``). :meth:`Heightfield.height_at`
evaluates exactly that surface, and the PyBullet world builds a transposed, x-reversed, 90°-yawed
copy so that Bullet's other diagonal lands on the same one (ray casts in both engines agree:
``tests/test_terrain.py``).

Generators (all seeded through an int seed, a :class:`numpy.random.SeedSequence` or a
:class:`numpy.random.Generator`): ``flat``, ``lumpy`` (Gaussian bumps like foam under turf),
``fractal`` (spectral fBm noise), ``steps`` (stairs along +x), ``slope`` (incline along +x),
``gaussian`` (a Gaussian random field of a given RMS height: the diagnosis's model of uneven
ground). Each keeps a flat start pad of radius ``start_radius`` [m] around the origin so the robot
can be placed; the pad blends smoothly.

Generator spec: every generator stores how it was called in :attr:`Heightfield.spec`, a JSON-plain
dict that :func:`from_spec` turns back into the same heights (bit for bit)::

    {"generator": "lumpy",                       # one of TERRAINS: the function that built it
     "seed": 3,                                  # int seed, or the stream's seed sequence:
     # "seed": {"entropy": 3, "spawn_key": [1]}  #   SeedSequence(entropy, spawn_key=(1,)) (+ "pool_size"
     #                                           #   when not 4); absent for flat and slope (no randomness)
     "amplitude": 0.02, "bump_radius": 0.08, "density": 40.0,   # the generator's other arguments,
     "size": [6.0, 3.0], "cell_size": 0.04, "start_radius": 0.25}  # all of them, by name

A :class:`numpy.random.Generator` passed as the seed is recorded by its seed sequence when it is a
fresh ``PCG64`` one (``np.random.default_rng(seed_or_seed_sequence)``, nothing drawn yet): that is how
the real world and the diagnosis build their fields. Any other generator (already drawn from, another
bit generator) cannot be replayed: the field's ``spec`` is then None. :meth:`Heightfield.to_dict`
(the recording metadata ``terrain``) carries the spec under ``"spec"``.
"""

from __future__ import annotations

import copy
import inspect
import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

#: Default field: 6 m x 3 m at 4 cm cells (151 x 76 nodes), robot spawned at the origin.
DEFAULT_SIZE = (6.0, 3.0)
DEFAULT_CELL = 0.04
TERRAINS = ("flat", "lumpy", "fractal", "steps", "slope", "gaussian")


@dataclass(frozen=True, eq=False)
class Heightfield:
    """Heights [m] on a regular grid centred at the origin.

    Args:
        heights: array of shape (ny, nx), ny, nx >= 2, finite values [m].
        cell_size: grid spacing [m] (> 0), the same along x and y.
        name: a label for reports (e.g. ``"lumpy(a=0.02)"``).
        spec: how a generator built it (see the module docstring; :func:`from_spec` rebuilds it),
            or None (heights from elsewhere, or a generator stream that cannot be replayed).

    Raises:
        ValueError: wrong shape, non-finite heights, non-positive cell size, or a spec that is not
            a dict naming its ``generator``.
    """

    heights: np.ndarray
    cell_size: float
    name: str = "custom"
    spec: dict | None = None

    def __post_init__(self) -> None:
        h = np.ascontiguousarray(self.heights, dtype=np.float64)
        if h.ndim != 2 or min(h.shape) < 2:
            raise ValueError(f"heights must have shape (ny, nx) with ny, nx >= 2, got {h.shape}")
        if not np.all(np.isfinite(h)):
            raise ValueError("heights contain NaN or infinite values")
        if not (np.isfinite(self.cell_size) and self.cell_size > 0):
            raise ValueError(f"cell_size must be a positive number of metres, got {self.cell_size!r}")
        if self.spec is not None:
            if not (isinstance(self.spec, Mapping) and isinstance(self.spec.get("generator"), str)):
                raise ValueError(f"spec must be a dict with a 'generator' name, got {self.spec!r}")
            object.__setattr__(self, "spec", _plain(dict(self.spec)))
        h.setflags(write=False)
        object.__setattr__(self, "heights", h)
        object.__setattr__(self, "cell_size", float(self.cell_size))

    # ------------------------------------------------------------------ geometry
    @property
    def shape(self) -> tuple[int, int]:
        return self.heights.shape

    @property
    def half_extent(self) -> tuple[float, float]:
        """(half_x, half_y) [m]: the field spans [-half_x, half_x] x [-half_y, half_y]."""
        ny, nx = self.heights.shape
        return (nx - 1) * self.cell_size / 2.0, (ny - 1) * self.cell_size / 2.0

    @property
    def x(self) -> np.ndarray:
        """Node x coordinates [m], shape (nx,)."""
        return -self.half_extent[0] + self.cell_size * np.arange(self.heights.shape[1])

    @property
    def y(self) -> np.ndarray:
        """Node y coordinates [m], shape (ny,)."""
        return -self.half_extent[1] + self.cell_size * np.arange(self.heights.shape[0])

    @property
    def min_height(self) -> float:
        return float(self.heights.min())

    @property
    def max_height(self) -> float:
        return float(self.heights.max())

    def height_at(self, x, y) -> np.ndarray:
        """Surface height [m] at points (x, y) [m] (arrays broadcast), MuJoCo's triangulation.

        Each cell is split along the diagonal from (x0, y0) to (x1, y1): for local fractions
        (u, v) in the cell, u >= v lies in the triangle (00, 10, 11), else in (00, 01, 11).

        Raises:
            ValueError: a point lies outside the field.
        """
        x = np.asarray(x, dtype=float)
        y = np.asarray(y, dtype=float)
        hx, hy = self.half_extent
        if np.any(np.abs(x) > hx + 1e-12) or np.any(np.abs(y) > hy + 1e-12):
            raise ValueError(f"points outside the heightfield (|x| <= {hx:g} m, |y| <= {hy:g} m)")
        return triangulated_height(self.heights[None], 0, x, y, self.cell_size, hx, hy)

    def roughness(self) -> float:
        """Standard deviation of the node heights [m]."""
        return float(self.heights.std())

    def to_dict(self) -> dict:
        """Metadata (no heights): name, shape, cell size, min/max [m], and ``spec`` (a copy of
        :attr:`spec`) when the field has one."""
        out = {"name": self.name, "shape": list(self.shape), "cell_size": self.cell_size,
               "min": self.min_height, "max": self.max_height}
        if self.spec is not None:
            out["spec"] = copy.deepcopy(self.spec)
        return out


def triangulated_height(heights: np.ndarray, k, x, y, cell_size: float, half_x: float, half_y: float) -> np.ndarray:
    """Height [m] of field ``heights[k]`` at (x, y) [m] on MuJoCo's triangulation of its cells.

    The one formula behind :meth:`Heightfield.height_at` and :class:`envs.base.GroundStack` (several
    episodes' fields of one shape, one point each, in one vectorized call): the same elementwise
    IEEE operations, so a point's height is bit-identical whichever way it is asked for.

    Args:
        heights: stacked node heights, shape (K, ny, nx) [m].
        k: which field per point (an int, or an int array broadcasting with x and y).
        x, y: points [m] inside the fields (the caller checks or clips the range).
        cell_size: grid spacing [m]; half_x, half_y: the fields' half extents [m].

    Returns:
        Heights [m], the broadcast shape of ``k``, ``x`` and ``y``.
    """
    ny, nx = heights.shape[-2:]
    fx = (x + half_x) / cell_size
    fy = (y + half_y) / cell_size
    ix = np.clip(np.floor(fx).astype(int), 0, nx - 2)
    iy = np.clip(np.floor(fy).astype(int), 0, ny - 2)
    u = fx - ix
    v = fy - iy
    h00, h10, h01, h11 = heights[k, iy, ix], heights[k, iy, ix + 1], heights[k, iy + 1, ix], heights[k, iy + 1, ix + 1]
    lower = h00 + u * (h10 - h00) + v * (h11 - h10)   # u >= v: triangle 00-10-11
    upper = h00 + v * (h01 - h00) + u * (h11 - h01)   # u <  v: triangle 00-01-11
    return np.where(u >= v, lower, upper)


# ---------------------------------------------------------------------------- generators
def _rng(seed) -> np.random.Generator:
    return seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)


def _plain(v):
    """``v`` with NumPy scalars/arrays and tuples turned into JSON-plain Python values."""
    if isinstance(v, Mapping):
        return {str(k): _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple, np.ndarray)):
        return [_plain(x) for x in v]
    if isinstance(v, np.generic):
        return v.item()
    return v


def _seed_spec(seed, rng: np.random.Generator):
    """The spec's ``seed``: what rebuilds ``rng``'s stream (call before drawing from it), or None
    when it cannot be recorded (a generator already drawn from, or not ``PCG64``)."""
    if isinstance(seed, (int, np.integer)):
        return int(seed)
    bg = rng.bit_generator
    ss = getattr(bg, "seed_seq", None)
    if type(bg) is not np.random.PCG64 or not isinstance(ss, np.random.SeedSequence):
        return None
    if np.random.PCG64(ss).state != bg.state:  # numbers already drawn: the stream has moved on
        return None
    out = {"entropy": _plain(ss.entropy), "spawn_key": [int(k) for k in ss.spawn_key]}
    if ss.pool_size != 4:
        out["pool_size"] = int(ss.pool_size)
    return out


def _seed_from_spec(s):
    """Inverse of :func:`_seed_spec`: an int, or the :class:`numpy.random.SeedSequence`."""
    if isinstance(s, bool) or s is None:
        raise ValueError(f"terrain spec seed must be an int or {{entropy, spawn_key}}, got {s!r}")
    if isinstance(s, (int, np.integer)):
        return int(s)
    if isinstance(s, Mapping) and "entropy" in s:
        try:
            return np.random.SeedSequence(s["entropy"], spawn_key=tuple(int(k) for k in s.get("spawn_key", ())),
                                          pool_size=int(s.get("pool_size", 4)))
        except (TypeError, ValueError) as exc:
            raise ValueError(f"terrain spec seed {s!r} is not a seed sequence: {exc}") from None
    raise ValueError(f"terrain spec seed must be an int or {{entropy, spawn_key}}, got {s!r}")


def _spec(generator: str, seed=None, *, seeded: bool = True, **args) -> dict | None:
    """A generator's spec (module docstring); None when its seed could not be recorded."""
    if seeded and seed is None:
        return None
    out = {"generator": generator}
    if seeded:
        out["seed"] = seed
    out.update(args)
    return _plain(out)


def _grid(size, cell_size):
    sx, sy = size
    if not (sx > 0 and sy > 0 and cell_size > 0):
        raise ValueError(f"size and cell_size must be positive, got size={size}, cell_size={cell_size}")
    nx = int(round(sx / cell_size)) + 1
    ny = int(round(sy / cell_size)) + 1
    x = (np.arange(nx) - (nx - 1) / 2.0) * cell_size
    y = (np.arange(ny) - (ny - 1) / 2.0) * cell_size
    return np.meshgrid(x, y)  # X, Y of shape (ny, nx)


def _start_pad(X, Y, start_radius: float) -> np.ndarray:
    """Weight in [0, 1]: 0 inside ``start_radius`` of the origin, smooth ramp to 1 over 0.15 m."""
    if start_radius <= 0:
        return np.ones_like(X)
    r = np.hypot(X, Y)
    t = np.clip((r - start_radius) / 0.15, 0.0, 1.0)
    return t * t * (3 - 2 * t)


def flat(size=DEFAULT_SIZE, cell_size=DEFAULT_CELL, height: float = 0.0) -> Heightfield:
    """A flat field at ``height`` [m]."""
    X, _ = _grid(size, cell_size)
    return Heightfield(np.full(X.shape, float(height)), cell_size, "flat",
                       _spec("flat", seeded=False, size=size, cell_size=cell_size, height=height))


def lumpy(seed=0, amplitude: float = 0.02, bump_radius: float = 0.08, density: float = 40.0,
          size=DEFAULT_SIZE, cell_size=DEFAULT_CELL, start_radius: float = 0.25) -> Heightfield:
    """Random Gaussian bumps and dents, like foam under artificial turf.

    Bumps of random sign and height in [0.3, 1] * ``amplitude`` with standard deviation
    ``bump_radius`` [m] are scattered at ``density`` bumps per m^2; the sum is rescaled so that
    the largest excursion from 0 equals ``amplitude`` [m].

    Raises:
        ValueError: negative amplitude, non-positive bump radius or density.
    """
    if amplitude < 0 or bump_radius <= 0 or density <= 0:
        raise ValueError(f"lumpy terrain needs amplitude >= 0, bump_radius > 0, density > 0; got "
                         f"{amplitude}, {bump_radius}, {density}")
    rng = _rng(seed)
    spec = _spec("lumpy", _seed_spec(seed, rng), amplitude=amplitude, bump_radius=bump_radius, density=density,
                 size=size, cell_size=cell_size, start_radius=start_radius)
    X, Y = _grid(size, cell_size)
    n = max(1, int(density * size[0] * size[1]))
    cx = rng.uniform(X.min(), X.max(), n)
    cy = rng.uniform(Y.min(), Y.max(), n)
    amp = rng.uniform(0.3, 1.0, n) * rng.choice([-1.0, 1.0], n)
    h = np.zeros_like(X)
    r = 3.0 * bump_radius  # truncate each Gaussian at 3 sigma: local windows keep this O(n)
    k = int(np.ceil(r / cell_size))
    ny, nx = X.shape
    x0, y0 = X[0, 0], Y[0, 0]
    for bx, by, a in zip(cx, cy, amp):
        ix, iy = int(round((bx - x0) / cell_size)), int(round((by - y0) / cell_size))
        sx = slice(max(ix - k, 0), min(ix + k + 1, nx))
        sy = slice(max(iy - k, 0), min(iy + k + 1, ny))
        d2 = (X[sy, sx] - bx) ** 2 + (Y[sy, sx] - by) ** 2
        h[sy, sx] += a * np.exp(-0.5 * d2 / bump_radius**2)
    h *= _start_pad(X, Y, start_radius)
    peak = np.abs(h).max()
    if peak > 0:
        h *= amplitude / peak
    return Heightfield(h, cell_size, f"lumpy(a={amplitude:g},r={bump_radius:g})", spec)


def fractal(seed=0, amplitude: float = 0.02, hurst: float = 0.8, min_wavelength: float = 0.1,
            size=DEFAULT_SIZE, cell_size=DEFAULT_CELL, start_radius: float = 0.25) -> Heightfield:
    """Fractal (fractional Brownian motion) noise by spectral synthesis.

    Power spectrum ~ f^-(2H+2) with Hurst exponent ``hurst`` in (0, 1), wavelengths below
    ``min_wavelength`` [m] removed; scaled so the largest excursion from 0 is ``amplitude`` [m].
    """
    if amplitude < 0 or not (0 < hurst < 1) or min_wavelength <= 0:
        raise ValueError("fractal terrain needs amplitude >= 0, 0 < hurst < 1, min_wavelength > 0")
    rng = _rng(seed)
    spec = _spec("fractal", _seed_spec(seed, rng), amplitude=amplitude, hurst=hurst, min_wavelength=min_wavelength,
                 size=size, cell_size=cell_size, start_radius=start_radius)
    X, Y = _grid(size, cell_size)
    ny, nx = X.shape
    fx = np.fft.fftfreq(nx, cell_size)
    fy = np.fft.fftfreq(ny, cell_size)
    F = np.hypot(*np.meshgrid(fx, fy))
    amp_spec = np.zeros_like(F)
    keep = (F > 0) & (F <= 1.0 / min_wavelength)
    amp_spec[keep] = F[keep] ** (-(hurst + 1.0))
    noise = rng.standard_normal((ny, nx)) + 1j * rng.standard_normal((ny, nx))
    h = np.real(np.fft.ifft2(noise * amp_spec))
    h -= h.mean()
    h *= _start_pad(X, Y, start_radius)
    peak = np.abs(h).max()
    if peak > 0:
        h *= amplitude / peak
    return Heightfield(h, cell_size, f"fractal(a={amplitude:g},H={hurst:g})", spec)


def gaussian(seed=0, rms_height: float = 0.003, correlation_radius: float = 0.08, size=DEFAULT_SIZE,
             cell_size=DEFAULT_CELL, start_radius: float = 0.25) -> Heightfield:
    """A Gaussian random surface: white noise smoothed by a Gaussian kernel of standard deviation
    ``correlation_radius`` [m] (``scipy.ndimage.gaussian_filter``, periodic edges), mean 0, scaled
    to RMS height ``rms_height`` [m] (Sq, ISO 25178) before the flat start pad is blended in.

    This is the uneven-ground model of the mismatch diagnosis (``sysid.roughness``): what a fitted
    RMS height means as a surface.

    Raises:
        ValueError: negative RMS height or non-positive correlation radius.
    """
    from scipy.ndimage import gaussian_filter

    if rms_height < 0 or not correlation_radius > 0:
        raise ValueError(f"gaussian terrain needs rms_height >= 0 and correlation_radius > 0, got {rms_height}, "
                         f"{correlation_radius}")
    rng = _rng(seed)
    spec = _spec("gaussian", _seed_spec(seed, rng), rms_height=rms_height, correlation_radius=correlation_radius,
                 size=size, cell_size=cell_size, start_radius=start_radius)
    X, Y = _grid(size, cell_size)
    if rms_height == 0:
        return Heightfield(np.zeros_like(X), cell_size, "gaussian(sq=0)", spec)
    h = gaussian_filter(rng.standard_normal(X.shape), correlation_radius / cell_size, mode="wrap")
    h -= h.mean()
    h *= rms_height / h.std()
    h *= _start_pad(X, Y, start_radius)
    return Heightfield(h, cell_size, f"gaussian(sq={rms_height:g},r={correlation_radius:g})", spec)


def steps(seed=0, amplitude: float = 0.02, step_length: float = 0.3, size=DEFAULT_SIZE,
          cell_size=DEFAULT_CELL, start_radius: float = 0.25) -> Heightfield:
    """Stairs along +x: every ``step_length`` [m] the height changes by a random amount in
    [-``amplitude``, ``amplitude``] [m] (up or down), starting past the start pad."""
    if amplitude < 0 or step_length <= 0:
        raise ValueError("steps terrain needs amplitude >= 0 and step_length > 0")
    rng = _rng(seed)
    spec = _spec("steps", _seed_spec(seed, rng), amplitude=amplitude, step_length=step_length, size=size,
                 cell_size=cell_size, start_radius=start_radius)
    X, Y = _grid(size, cell_size)
    x = X[0]
    edges = np.arange(start_radius, x.max() + step_length, step_length)
    rises = rng.uniform(-amplitude, amplitude, len(edges))
    level = np.zeros_like(x)
    for e, dh in zip(edges, rises):
        level[x >= e] += dh
    # mirror for x < 0 so walking backwards meets steps too
    back = np.arange(-start_radius, x.min() - step_length, -step_length)
    for e, dh in zip(back, rng.uniform(-amplitude, amplitude, len(back))):
        level[x <= e] += dh
    return Heightfield(np.broadcast_to(level, X.shape).copy(), cell_size, f"steps(a={amplitude:g})", spec)


def slope(seed=0, amplitude: float = 0.05, size=DEFAULT_SIZE, cell_size=DEFAULT_CELL,
          start_radius: float = 0.25) -> Heightfield:
    """An incline along +x with grade ``amplitude`` (rise per metre; 0.05 = 5 %, 2.9°), flat
    within ``start_radius`` [m] of the origin. ``seed`` is accepted for a uniform signature."""
    del seed
    X, _ = _grid(size, cell_size)
    h = amplitude * np.where(np.abs(X) > start_radius, np.sign(X) * (np.abs(X) - start_radius), 0.0)
    return Heightfield(h, cell_size, f"slope(grade={amplitude:g})",
                       _spec("slope", seeded=False, amplitude=amplitude, size=size, cell_size=cell_size,
                             start_radius=start_radius))


#: Largest amplitude per kind a command accepts: bump/step height [m], slope grade, RMS height [m].
MAX_AMPLITUDE = {"flat": 0.0, "lumpy": 0.2, "fractal": 0.2, "steps": 0.2, "slope": 0.5, "gaussian": 0.05}


def check_amplitude(kind: str, amplitude: float) -> float:
    """``amplitude`` if it is a finite value within [0, MAX_AMPLITUDE[kind]] (0 for flat ground).

    Raises:
        ValueError: unknown kind, or an amplitude outside that range (named with its unit).
    """
    if kind not in MAX_AMPLITUDE:
        raise ValueError(f"unknown terrain {kind!r}; choose one of {', '.join(TERRAINS)}")
    if kind == "flat":
        return 0.0
    hi = MAX_AMPLITUDE[kind]
    unit = "grade" if kind == "slope" else "m"
    if not (math.isfinite(amplitude) and 0 <= amplitude <= hi):
        raise ValueError(f"terrain amplitude for {kind} must be within [0, {hi:g}] {unit}, got {amplitude!r}")
    return float(amplitude)


def make(kind: str, seed=0, amplitude: float = 0.02, **kwargs) -> Heightfield:
    """Build terrain ``kind`` (one of :data:`TERRAINS`) with ``amplitude`` [m] from ``seed`` (for
    ``gaussian`` the amplitude is the RMS height; for ``slope`` the grade).

    Raises:
        ValueError: unknown kind.
    """
    if kind == "flat":
        return flat(**{k: v for k, v in kwargs.items() if k in ("size", "cell_size")})
    if kind == "gaussian":
        return gaussian(seed=seed, rms_height=amplitude, **kwargs)
    gens = {"lumpy": lumpy, "fractal": fractal, "steps": steps, "slope": slope}
    if kind not in gens:
        raise ValueError(f"unknown terrain {kind!r}; choose one of {', '.join(TERRAINS)}")
    return gens[kind](seed=seed, amplitude=amplitude, **kwargs)


#: Generator functions by spec name (:data:`TERRAINS`).
GENERATORS = {"flat": flat, "lumpy": lumpy, "fractal": fractal, "steps": steps, "slope": slope, "gaussian": gaussian}


def from_spec(spec: Mapping) -> Heightfield:
    """Rebuild the heightfield a generator made from its :attr:`Heightfield.spec` (heights identical
    bit for bit; see the module docstring for the format).

    Raises:
        ValueError: not a spec, an unknown generator, arguments the generator does not take, a seed
            that is neither an int nor ``{entropy, spawn_key}``, or values the generator refuses
            (a value of the wrong type may raise the generator's TypeError).
    """
    if not isinstance(spec, Mapping) or "generator" not in spec:
        raise ValueError(f"a terrain spec is a dict with a 'generator' name, got {spec!r}")
    name = spec["generator"]
    gen = GENERATORS.get(name) if isinstance(name, str) else None
    if gen is None:
        raise ValueError(f"unknown terrain generator {name!r} in spec; choose one of {', '.join(TERRAINS)}")
    args = {k: v for k, v in spec.items() if k != "generator"}
    if "seed" in args:
        args["seed"] = _seed_from_spec(args["seed"])
    if "size" in args:
        args["size"] = tuple(args["size"])
    try:
        inspect.signature(gen).bind(**args)
    except TypeError as exc:
        raise ValueError(f"terrain spec does not fit {name}(): {exc}") from None
    return gen(**args)
