"""The 16 gait parameters of the ZMP walk engine: names, units, θ0, bounds, [0, 1] normalisation.

Source: this project's own 16-parameter set, built for this engine (a first-draft table whose θ0
and bounds were drawn from public NAO walks: rUNSWift Walk2014 (B. Hengst, UNSW report, 2014),
Rhoban placo, the Bit-Bots quintic walk and Aldebaran's walk; the
SGAT paper only says "the walk engine contains 16 parameters"). Changes against that table, each
forced by this project's robot model or by experiments (see also the ``note`` fields of
:data:`SPECS`):

* ``com_height``: the table's 0.235 m [0.200, 0.248] assumes a CoM 0.237 m above the soles in the
  walking crouch. The ``robots.nao`` model (V50 URDF masses, arms down) has its whole-body CoM
  0.263 m above the soles in that crouch (torso origin 0.313 m; ≈0.283 m straight-legged), so the
  bounds move up to [0.225, 0.275] (0.275: the support leg still reaches ±5 cm at 0.999 of its
  length). θ0 = 0.265 is the table's intent (the CoM of the walking crouch hip -0.45, knee 0.9,
  ankle -0.45 rad) translated to this model. It also keeps torque margin: at 0.255, before the
  engine's load compensation existed, the loaded support knee (≈1.1 rad) needed ≈2.7 of its
  3.02 N·m and, with the "real" profile's torque-limit scaling 0.75, fell in 3/3 flat trials
  (0.265: 0/3).
* No parameter was swapped: the candidates that are inert in the flat sim (``gyro_hip_roll_gain``,
  ``gyro_ankle_roll_gain``, ``preview_log10_R``, ``torso_pitch``, ``zmp_offset_y``: < 0.6 cm/s
  between their bounds) all change the fall rate on the "real" profile (10 seeds, θ0 4/10 falls:
  gyro_hip_roll_gain 0.15 -> 1/10, gyro_ankle_roll_gain 0.15 -> 2/10, preview_log10_R -3 -> 1/10,
  torso_pitch 0.25 -> 7/10).
* Other values/bounds: see the ``note`` of each :class:`ParamSpec`.

CMA-ES sees the vector ``(θ - low) / (high - low)`` in [0, 1]^16 (pycma's default ``BoundTransform``
handles the box; N. Hansen et al., pycma, https://github.com/CMA-ES/pycma).
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import os
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from common.files import atomic_write_text


@dataclass(frozen=True)
class ParamSpec:
    """One gait parameter: name, unit, initial value θ0, bounds [low, high], meaning, notes."""

    name: str
    unit: str
    init: float
    low: float
    high: float
    doc: str
    note: str = ""


#: The 16 parameters in vector order (the numbering of walk_engine/README.md, "Parameters").
SPECS: tuple[ParamSpec, ...] = (
    ParamSpec("step_period", "s", 0.30, 0.18, 0.60,
              "duration of one step = single + double support (half a gait cycle)"),
    ParamSpec("double_support_ratio", "-", 0.20, 0.00, 0.50,
              "fraction of a step with both feet on the ground (ZMP moves linearly across)"),
    ParamSpec("step_length", "m", 0.040, 0.000, 0.080,
              "forward advance per step at the default command (speed = step_length / step_period); "
              "also the forward limit of a commanded step"),
    ParamSpec("feet_spacing", "m", 0.100, 0.085, 0.140,
              "lateral distance between the sole frames (ankle projections), centre to centre"),
    ParamSpec("com_height", "m", 0.265, 0.225, 0.275,
              "LIPM height z_c of the preview controller; the torso is placed so that the whole-body "
              "CoM has this height above the soles",
              "reference 0.235 [0.200, 0.248] shifted: this model's CoM is 0.263 m in the crouch; "
              "θ0 0.265 keeps the support knee below its torque limit (module docstring)"),
    ParamSpec("torso_pitch", "rad", 0.05, -0.10, 0.25, "forward lean of the torso (rotation about y)"),
    ParamSpec("com_x_offset", "m", 0.010, -0.020, 0.030,
              "torso placed this far ahead of where the LIPM plan puts it (absorbs model error)"),
    ParamSpec("zmp_offset_x", "m", 0.010, -0.020, 0.040,
              "ZMP reference ahead of the ankle projection of the support foot"),
    ParamSpec("zmp_offset_y", "m", 0.000, -0.030, 0.020,
              "ZMP reference outward (away from the other foot) of the ankle projection"),
    ParamSpec("preview_log10_R", "-", -6.0, -8.0, -3.0,
              "log10 of the jerk weight R (Q_e = 1) of the Kajita preview controller"),
    ParamSpec("step_height", "m", 0.020, 0.005, 0.050, "swing-foot apex height above the ground"),
    ParamSpec("swing_apex_plateau", "-", 0.20, 0.00, 0.60,
              "fraction of the single-support phase the swing foot holds its apex height"),
    ParamSpec("gyro_ankle_pitch_gain", "rad/(rad/s)", 0.04, 0.00, 0.15,
              "low-passed torso pitch rate added to the support ankle pitch"),
    ParamSpec("gyro_ankle_roll_gain", "rad/(rad/s)", 0.03, 0.00, 0.15,
              "low-passed torso roll rate added to the support ankle roll"),
    ParamSpec("gyro_hip_roll_gain", "rad/(rad/s)", 0.02, 0.00, 0.15,
              "low-passed torso roll rate added to the support hip roll"),
    ParamSpec("support_hip_roll_comp", "rad", 0.02, -0.02, 0.10,
              "feed-forward hip-roll added to the support leg in single support (against hip sag)"),
)

NAMES: tuple[str, ...] = tuple(s.name for s in SPECS)
N_PARAMS = len(SPECS)
LOW = np.array([s.low for s in SPECS])
HIGH = np.array([s.high for s in SPECS])
INIT = np.array([s.init for s in SPECS])
_SPEC = {s.name: s for s in SPECS}


def spec(name: str) -> ParamSpec:
    """The :class:`ParamSpec` of ``name``; raises ValueError naming the known parameters."""
    if name not in _SPEC:
        raise ValueError(f"unknown gait parameter {name!r}; known: {', '.join(NAMES)}")
    return _SPEC[name]


def _check(values: dict, specs: tuple[ParamSpec, ...] = SPECS) -> None:
    """Raise one ValueError naming every missing, extra, non-numeric, non-finite or out-of-bounds value
    (bounds of ``specs``: the NAO's, or a robot's, :func:`params_for`)."""
    problems = []
    by_name = {s.name: s for s in specs}
    missing = [n for n in NAMES if n not in values]
    extra = [str(k) for k in values if k not in _SPEC]
    if missing:
        problems.append(f"missing {', '.join(missing)}")
    if extra:
        problems.append(f"unknown {', '.join(extra)} (known: {', '.join(NAMES)})")
    bad_type, nonfinite, oob = [], [], []
    for n in NAMES:
        if n not in values:
            continue
        v = values[n]
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
            bad_type.append(f"{n}={v!r}")
            continue
        v = float(v)
        if not math.isfinite(v):
            nonfinite.append(f"{n}={v}")
            continue
        s = by_name[n]
        if not (s.low - 1e-12 <= v <= s.high + 1e-12):
            oob.append(f"{n}={v:g} {s.unit} not in [{s.low:g}, {s.high:g}]")
    if bad_type:
        problems.append(f"not a number: {', '.join(bad_type)}")
    if nonfinite:
        problems.append(f"non-finite: {', '.join(nonfinite)}")
    if oob:
        problems.append(f"out of bounds: {', '.join(oob)}")
    if problems:
        raise ValueError("invalid gait parameters: " + "; ".join(problems))


@dataclass(frozen=True)
class GaitParams:
    """The 16 gait parameters θ of the walk engine (SI units; see :data:`SPECS` for units,
    θ0 and bounds). Construction validates: every value finite and within its bounds.

    The class is the NAO's; :func:`params_for` gives each other robot a subclass with its own θ0
    and bounds (class attributes ``robot``, ``specs``, ``length_scale``).

    Raises:
        ValueError: naming each non-finite, non-numeric or out-of-bounds parameter.
    """

    robot: ClassVar[str] = "nao"
    specs: ClassVar[tuple[ParamSpec, ...]] = SPECS
    #: leg length of the robot / the NAO's (the footstep planner scales its step limits by it)
    length_scale: ClassVar[float] = 1.0

    step_period: float = _SPEC["step_period"].init
    double_support_ratio: float = _SPEC["double_support_ratio"].init
    step_length: float = _SPEC["step_length"].init
    feet_spacing: float = _SPEC["feet_spacing"].init
    com_height: float = _SPEC["com_height"].init
    torso_pitch: float = _SPEC["torso_pitch"].init
    com_x_offset: float = _SPEC["com_x_offset"].init
    zmp_offset_x: float = _SPEC["zmp_offset_x"].init
    zmp_offset_y: float = _SPEC["zmp_offset_y"].init
    preview_log10_R: float = _SPEC["preview_log10_R"].init
    step_height: float = _SPEC["step_height"].init
    swing_apex_plateau: float = _SPEC["swing_apex_plateau"].init
    gyro_ankle_pitch_gain: float = _SPEC["gyro_ankle_pitch_gain"].init
    gyro_ankle_roll_gain: float = _SPEC["gyro_ankle_roll_gain"].init
    gyro_hip_roll_gain: float = _SPEC["gyro_hip_roll_gain"].init
    support_hip_roll_comp: float = _SPEC["support_hip_roll_comp"].init

    def __post_init__(self) -> None:
        vals = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        _check(vals, type(self).specs)
        for k, v in vals.items():
            object.__setattr__(self, k, float(v))

    # ------------------------------------------------------------------ conversions
    @classmethod
    def initial(cls) -> "GaitParams":
        """θ0, the initial parameter set."""
        return cls()

    @classmethod
    def from_dict(cls, d: dict) -> "GaitParams":
        """From a mapping with exactly the 16 names.

        Raises:
            ValueError: naming every missing, unknown, non-numeric, non-finite or out-of-bounds entry.
        """
        if not isinstance(d, dict):
            raise ValueError(f"gait parameters must be a mapping of the 16 names to numbers, got {type(d).__name__}")
        _check(d, cls.specs)
        return cls(**{n: float(d[n]) for n in NAMES})

    def to_dict(self) -> dict[str, float]:
        """Name -> value (SI), in vector order."""
        return {n: getattr(self, n) for n in NAMES}

    def to_array(self) -> np.ndarray:
        """Raw values in SI units, shape (16,), in :data:`NAMES` order."""
        return np.array([getattr(self, n) for n in NAMES])

    @classmethod
    def from_array(cls, x) -> "GaitParams":
        """From raw SI values, shape (16,).

        Raises:
            ValueError: wrong length; non-finite or out-of-bounds values (named).
        """
        x = np.asarray(x, dtype=float).ravel()
        if x.shape != (N_PARAMS,):
            raise ValueError(f"expected {N_PARAMS} gait parameters ({', '.join(NAMES)}), got {x.size}")
        return cls.from_dict(dict(zip(NAMES, x.tolist())))

    def to_vector(self) -> np.ndarray:
        """Normalised vector u = (θ - low) / (high - low) in [0, 1]^16 (the space CMA-ES searches)."""
        low, high = _bounds(type(self))
        return (self.to_array() - low) / (high - low)

    @classmethod
    def from_vector(cls, u, clip: bool = False) -> "GaitParams":
        """Inverse of :meth:`to_vector`: θ = low + u (high - low).

        Args:
            u: shape (16,), entries in [0, 1] (or anything finite if ``clip``).
            clip: clip u into [0, 1] first (for optimisers that step outside the box).

        Raises:
            ValueError: wrong length, non-finite entries, or (without ``clip``) entries outside
                [0, 1], naming the parameters.
        """
        u = np.asarray(u, dtype=float).ravel()
        if u.shape != (N_PARAMS,):
            raise ValueError(f"expected a normalised vector of {N_PARAMS} entries ({', '.join(NAMES)}), got {u.size}")
        bad = [NAMES[i] for i in np.flatnonzero(~np.isfinite(u))]
        if bad:
            raise ValueError(f"normalised gait vector has non-finite entries: {', '.join(bad)}")
        if clip:
            u = np.clip(u, 0.0, 1.0)
        else:
            out = [f"{NAMES[i]}={u[i]:g}" for i in np.flatnonzero((u < -1e-12) | (u > 1 + 1e-12))]
            if out:
                raise ValueError(f"normalised gait vector outside [0, 1]: {', '.join(out)}")
            u = np.clip(u, 0.0, 1.0)
        low, high = _bounds(cls)
        return cls.from_array(low + u * (high - low))

    def replace(self, **changes) -> "GaitParams":
        """A copy with some parameters changed (validated)."""
        unknown = [k for k in changes if k not in _SPEC]
        if unknown:
            raise ValueError(f"unknown gait parameter(s) {', '.join(unknown)}; known: {', '.join(NAMES)}")
        return dataclasses.replace(self, **changes)

    # ------------------------------------------------------------------ JSON
    def save(self, path: str | os.PathLike) -> str:
        """Write ``{"params": {name: value}, "units": {...}}`` as JSON atomically; returns the path."""
        path = os.fspath(path)
        doc = {"params": self.to_dict(), "units": {s.name: s.unit for s in self.specs}}
        if self.robot != "nao":
            doc["robot"] = self.robot
        atomic_write_text(path, json.dumps(doc, indent=2) + "\n")
        return path

    @classmethod
    def load(cls, path: str | os.PathLike) -> "GaitParams":
        """Read a JSON file written by :meth:`save`, or a plain ``{name: value}`` object.

        Raises:
            FileNotFoundError: no such file.
            ValueError: unreadable JSON, wrong structure, or invalid values (named), with the path.
        """
        path = os.fspath(path)
        if not os.path.exists(path):
            raise FileNotFoundError(f"no gait parameter file at {path!r}")
        try:
            with open(path) as f:
                doc = json.load(f)
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise ValueError(f"{path!r} is not valid JSON: {exc}") from None
        except OSError as exc:
            raise ValueError(f"cannot read {path!r}: {exc}") from None
        if isinstance(doc, dict) and doc.get("robot", cls.robot) != cls.robot:
            raise ValueError(f"{path!r} holds gait parameters of robot {doc['robot']!r}, not {cls.robot!r}")
        if isinstance(doc, dict) and isinstance(doc.get("params"), dict):
            doc = doc["params"]
        if not isinstance(doc, dict):
            raise ValueError(f"{path!r}: expected a JSON object of the 16 gait parameters")
        try:
            return cls.from_dict(doc)
        except ValueError as exc:
            raise ValueError(f"{path!r}: {exc}") from None

    def describe(self) -> str:
        """A human-readable table: name, value, unit, bounds."""
        rows = [f"{s.name:24s} {getattr(self, s.name):10.4g} {s.unit:12s} [{s.low:g}, {s.high:g}]" for s in self.specs]
        return "\n".join(rows)


def _bounds(cls) -> tuple[np.ndarray, np.ndarray]:
    """(low, high) arrays (16,) of a :class:`GaitParams` class (the module's LOW/HIGH for the NAO)."""
    if cls.specs is SPECS:
        return LOW, HIGH
    return np.array([s.low for s in cls.specs]), np.array([s.high for s in cls.specs])


#: How each parameter scales with the robot (:func:`scaled_specs`): stride lengths with the leg,
#: offsets inside the footprint with the foot.
LENGTHS = ("step_length", "step_height")
FOOT_LENGTHS = ("com_x_offset", "zmp_offset_x", "zmp_offset_y")
TIMES = ("step_period", "gyro_ankle_pitch_gain", "gyro_ankle_roll_gain", "gyro_hip_roll_gain")
#: The NAO's reference geometry [m] (robots.nao): leg length hip -> sole, hip width, and the
#: whole-body CoM above the soles in the crouch and straight (zero-leg) poses.
NAO_LEG_LENGTH = 0.085 + 0.100 + 0.1029 + 0.04511 - 0.085
NAO_HIP_WIDTH = 0.100
NAO_FOOT_LENGTH = 0.160
NAO_COM_CROUCH, NAO_COM_STRAIGHT = 0.263, 0.283


def scaled_specs(leg_length: float, hip_width: float, com_crouch: float, com_straight: float,
                 foot_length: float = NAO_FOOT_LENGTH) -> tuple[tuple[ParamSpec, ...], float]:
    """The 16 parameters for another robot, scaled from the NAO's (dynamic similarity: lengths with
    the leg length ratio λ, times with sqrt(λ) at equal Froude number v²/(g l); Alexander & Jayes,
    "A dynamic similarity hypothesis for the gaits of quadrupedal mammals", J. Zool. 201, 1983,
    the scaling biped walk engines inherit):

    * stride lengths (:data:`LENGTHS`) × λ; offsets inside the footprint (:data:`FOOT_LENGTHS`:
      where the CoM and the ZMP sit over the sole) × the foot length ratio (a G1's sole is 1.1× the
      NAO's, its leg 2.8×: offsets scaled with the leg put the CoM at the toes); the step period and
      the gyro gains (rad per rad/s) × sqrt(λ);
    * ``feet_spacing``: θ0 = the robot's hip width, bounds at the NAO's ratios (0.85, 1.4);
    * ``com_height``: placed between the robot's crouch and straight-leg CoM heights as the NAO's
      θ0 and bounds are (θ0 = crouch + 0.1·(straight − crouch), low = crouch − 1.9·(...), high =
      crouch + 0.6·(...));
    * angles and ratios unchanged.

    Args:
        leg_length: hip joint to sole with straight legs [m]; hip_width: distance between the soles
            with straight legs [m]; com_crouch, com_straight: CoM height above the soles [m] in the
            two poses; foot_length: sole length [m].

    Returns:
        (specs, λ).
    """
    lam = leg_length / NAO_LEG_LENGTH
    span = com_straight - com_crouch
    out = []
    for s in SPECS:
        if s.name in LENGTHS or s.name in FOOT_LENGTHS:
            k = lam if s.name in LENGTHS else foot_length / NAO_FOOT_LENGTH
            s = dataclasses.replace(s, init=s.init * k, low=s.low * k, high=s.high * k)
        elif s.name in TIMES:
            k = math.sqrt(lam)
            s = dataclasses.replace(s, init=s.init * k, low=s.low * k, high=s.high * k)
        elif s.name == "feet_spacing":  # the NAO's θ0 and bounds relative to its hip width
            k = hip_width / NAO_HIP_WIDTH
            s = dataclasses.replace(s, init=s.init * k, low=s.low * k, high=s.high * k)
        elif s.name == "com_height":  # the NAO's, relative to its crouch and straight-leg CoM heights
            def place(v):
                return com_crouch + (v - NAO_COM_CROUCH) / (NAO_COM_STRAIGHT - NAO_COM_CROUCH) * span

            s = dataclasses.replace(s, init=place(s.init), low=place(s.low), high=place(s.high),
                                    note="scaled from the NAO's (scaled_specs)")
        out.append(dataclasses.replace(s, init=float(f"{s.init:.6g}"), low=float(f"{s.low:.6g}"),
                                       high=float(f"{s.high:.6g}")))
    return tuple(out), lam


@functools.lru_cache(maxsize=None)
def _params_class(robot_name: str, specs: tuple[ParamSpec, ...], lam: float) -> type:
    fields = [(s.name, float, dataclasses.field(default=s.init)) for s in specs]
    cls = dataclasses.make_dataclass(f"GaitParams_{robot_name}", fields, bases=(GaitParams,), frozen=True)
    cls.robot, cls.specs, cls.length_scale = robot_name, specs, lam
    cls.__doc__ = f"The 16 gait parameters for {robot_name} (θ0 and bounds scaled from the NAO's: scaled_specs)."
    return cls


def params_for(robot) -> type[GaitParams]:
    """The :class:`GaitParams` class of ``robot`` (a ``robots.RobotModel``): :class:`GaitParams` itself
    for the NAO, else a subclass whose θ0 and bounds come from :func:`scaled_specs` with the robot's
    geometry (leg length, hip width and CoM heights measured on its model; ``walk_engine.legs``)."""
    if robot.name == "nao":
        return GaitParams
    from walk_engine.legs import robot_geometry  # lazy: legs imports the robot kinematics

    specs, lam = scaled_specs(*robot_geometry(robot))
    return _params_class(robot.name, specs, lam)
