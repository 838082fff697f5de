"""The "real" world's extra physics: a documented, seeded profile of effects the sim leaves out.

A :class:`RealProfile` holds, for each effect, the range ``(low, high)`` a value is drawn from
uniformly at every episode reset (from the episode's seed); ``draw(rng, robot)`` returns the
:class:`EffectDraw` that the PyBullet world applies for that episode. Per-joint effects draw one
value per joint.

Effects and how the real world (``envs.bullet_world``) applies them:

=====================  ==========  ========================================================
field                  unit        implementation
=====================  ==========  ========================================================
kp_scale, kd_scale     --          per-joint scale of the PD gains inside the explicit PD loop
latency_s              s           command FIFO at the physics rate in front of the PD
                                   (``round(latency / physics_dt)`` physics steps)
backlash_rad           rad         per-joint dead band of that full width on the PD position
                                   error (gear play: no restoring torque inside the band)
coulomb_friction_nm    N m         per-joint PyBullet velocity motor with target 0 and max force
                                   = the friction torque, beside the PD torque
                                   (bullet3 ``examples/pybullet/examples/jointFrictionAndMotor.py``)
viscous_damping        N m s/rad   per-joint extra ``-b * qdot`` in the PD torque
torque_limit_scale     --          scales the URDF effort limit the PD torque is clipped to
mass_scale             --          per-link mass and inertia scale (``changeDynamics``)
foot_friction          --          absolute lateral friction coefficient of both feet
encoder_bias_rad       rad         per-joint calibration offset: seen by the servo and the
                                   encoder reading alike
encoder_noise_rad      rad         std of white noise on the measured joint positions
gyro_bias, gyro_noise  rad/s       per-axis gyro offset; std of white noise
accel_noise            m/s^2       std of white noise on the accelerometer
angle_noise_rad        rad         std of white noise on the torso roll/pitch estimate
terrain_amplitude      m           amplitude of the episode's lumpy heightfield
=====================  ==========  ========================================================

The values of the "real" profile are plausible for a NAO (real output torque 20-30 % below the URDF
effort: gearbox losses on the motor ratings x reduction ratios of the Aldebaran NAO6 datasheet; a
10-12 ms DCM cycle: Aldebaran NAOqi DCM documentation, 12 ms on NAO6; friction and backlash are
estimates). ``"none"`` draws the identity for every effect and flat ground: a real world that
should agree with the sim up to the engine gap. Two profiles split ``"real"`` in two, to find which
part of the gap a training world misses (``sgatwalk fidelity --profile``): ``"real-flat"`` is
``"real"`` on flat ground (every actuator, sensor and mass effect), ``"real-ground"`` only its uneven
ground. A seed draws the same values of the effects a profile keeps as ``"real"`` draws (every
profile draws every effect, in the same order), so trials on the same seeds pair across profiles.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

Range = tuple[float, float]

_IDENTITY: dict[str, float] = {
    "kp_scale": 1.0, "kd_scale": 1.0, "latency_s": 0.0, "backlash_rad": 0.0, "coulomb_friction_nm": 0.0,
    "viscous_damping": 0.0, "torque_limit_scale": 1.0, "mass_scale": 1.0, "foot_friction": 0.8,
    "encoder_bias_rad": 0.0, "encoder_noise_rad": 0.0, "gyro_bias": 0.0, "gyro_noise": 0.0,
    "accel_noise": 0.0, "angle_noise_rad": 0.0, "terrain_amplitude": 0.0,
}
#: Effects drawn once per joint (24 values) or per link (25 values); the rest are scalars,
#: except ``gyro_bias`` (3 values, one per axis).
PER_JOINT = ("kp_scale", "kd_scale", "backlash_rad", "coulomb_friction_nm", "viscous_damping", "encoder_bias_rad")
PER_LINK = ("mass_scale",)
EFFECTS = tuple(_IDENTITY)
#: Nominal foot friction coefficient, the same in the sim (RoboCup SPL robot-dimension code assumes 0.7).
NOMINAL_FOOT_FRICTION = _IDENTITY["foot_friction"]


def _fixed(v: float) -> Range:
    return (float(v), float(v))


@dataclass(frozen=True)
class RealProfile:
    """Ranges ``(low, high)`` of the real world's effects, drawn uniformly per episode.

    Raises:
        ValueError: a range is not two finite numbers with low <= high, or is physically invalid
            (negative latency/friction/noise, non-positive scales).
    """

    name: str = "custom"
    kp_scale: Range = _fixed(1.0)
    kd_scale: Range = _fixed(1.0)
    latency_s: Range = _fixed(0.0)
    backlash_rad: Range = _fixed(0.0)
    coulomb_friction_nm: Range = _fixed(0.0)
    viscous_damping: Range = _fixed(0.0)
    torque_limit_scale: Range = _fixed(1.0)
    mass_scale: Range = _fixed(1.0)
    foot_friction: Range = _fixed(NOMINAL_FOOT_FRICTION)
    encoder_bias_rad: Range = _fixed(0.0)
    encoder_noise_rad: Range = _fixed(0.0)
    gyro_bias: Range = _fixed(0.0)
    gyro_noise: Range = _fixed(0.0)
    accel_noise: Range = _fixed(0.0)
    angle_noise_rad: Range = _fixed(0.0)
    terrain_amplitude: Range = _fixed(0.0)

    def __post_init__(self) -> None:
        for f in EFFECTS:
            r = getattr(self, f)
            try:
                lo, hi = (float(r[0]), float(r[1]))
            except (TypeError, ValueError, IndexError):
                raise ValueError(f"effect {f!r}: expected a (low, high) pair, got {r!r}") from None
            if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi):
                raise ValueError(f"effect {f!r}: need finite low <= high, got ({lo}, {hi})")
            positive = f.endswith("_scale") or f == "foot_friction"
            if (positive and lo <= 0) or (not positive and f not in ("encoder_bias_rad", "gyro_bias") and lo < 0):
                raise ValueError(f"effect {f!r}: range ({lo}, {hi}) is out of its physical domain")
            object.__setattr__(self, f, (lo, hi))

    @property
    def is_identity(self) -> bool:
        """True if every effect is fixed at its identity value (the "none" profile)."""
        return all(getattr(self, f) == _fixed(_IDENTITY[f]) for f in EFFECTS)

    def active(self) -> list[str]:
        """Names of the effects that differ from identity."""
        return [f for f in EFFECTS if getattr(self, f) != _fixed(_IDENTITY[f])]

    def with_effect(self, name: str, value: float | Range, **kw) -> "RealProfile":
        """A copy with effect ``name`` set to ``value`` (a number = a fixed range)."""
        if name not in EFFECTS:
            raise ValueError(f"unknown effect {name!r}; known: {', '.join(EFFECTS)}")
        rng = value if isinstance(value, (tuple, list)) else _fixed(value)
        return dataclasses.replace(self, **{name: tuple(rng)}, **kw)

    def to_dict(self) -> dict:
        return {"name": self.name, **{f: list(getattr(self, f)) for f in EFFECTS}}

    @classmethod
    def from_dict(cls, d: dict) -> "RealProfile":
        unknown = set(d) - set(EFFECTS) - {"name"}
        if unknown:
            raise ValueError(f"unknown effect(s) {sorted(unknown)}; known: {', '.join(EFFECTS)}")
        return cls(**{k: (tuple(v) if k != "name" else v) for k, v in d.items()})

    def draw(self, rng: np.random.Generator, n_joints: int, n_links: int) -> "EffectDraw":
        """Draw one episode's effect values from ``rng`` (see :class:`EffectDraw`)."""
        vals = {}
        for f in EFFECTS:
            lo, hi = getattr(self, f)
            n = n_joints if f in PER_JOINT else n_links if f in PER_LINK else 3 if f == "gyro_bias" else None
            vals[f] = rng.uniform(lo, hi, n) if n else float(rng.uniform(lo, hi))
        return EffectDraw(profile=self.name, **vals)


@dataclass
class EffectDraw:
    """One episode's effect values: per-joint arrays (24,), per-link (25,), gyro_bias (3,), else floats."""

    profile: str
    kp_scale: np.ndarray
    kd_scale: np.ndarray
    latency_s: float
    backlash_rad: np.ndarray
    coulomb_friction_nm: np.ndarray
    viscous_damping: np.ndarray
    torque_limit_scale: float
    mass_scale: np.ndarray
    foot_friction: float
    encoder_bias_rad: np.ndarray
    encoder_noise_rad: float
    gyro_bias: np.ndarray
    gyro_noise: float
    accel_noise: float
    angle_noise_rad: float
    terrain_amplitude: float
    extra: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """JSON-able values (arrays as lists) for a recording's metadata."""
        out = {}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            out[f.name] = v.tolist() if isinstance(v, np.ndarray) else v
        return out


PROFILES: dict[str, RealProfile] = {
    "none": RealProfile("none"),
    "real": RealProfile(
        "real",
        kp_scale=(0.85, 1.0), kd_scale=(0.8, 1.2), latency_s=(0.010, 0.020), backlash_rad=(0.002, 0.006),
        coulomb_friction_nm=(0.02, 0.06), viscous_damping=(0.005, 0.02), torque_limit_scale=(0.75, 0.9),
        mass_scale=(0.95, 1.08), foot_friction=(0.5, 0.9), encoder_bias_rad=(-0.005, 0.005),
        encoder_noise_rad=(0.001, 0.001), gyro_bias=(-0.01, 0.01), gyro_noise=(0.01, 0.01),
        accel_noise=(0.1, 0.1), angle_noise_rad=(0.005, 0.005), terrain_amplitude=(0.005, 0.015)),
}


def _on_flat_ground(profile: RealProfile) -> RealProfile:
    """``profile``'s effects on flat ground, named ``"real-flat"``."""
    return dataclasses.replace(profile, name="real-flat", terrain_amplitude=_fixed(0.0))


#: ``"real"`` split in two (module docstring): its effects on flat ground, and its ground alone.
PROFILES["real-flat"] = _on_flat_ground(PROFILES["real"])
PROFILES["real-ground"] = dataclasses.replace(PROFILES["none"], name="real-ground",
                                              terrain_amplitude=PROFILES["real"].terrain_amplitude)


#: The "real" profile per actuator class, for the robots other than the NAO (estimates, not
#: measurements): the Unitree G1's quasi-direct-drive joints (low-ratio planetary gears) have little
#: backlash and more latency between command and torque (its low-level command loop runs through the
#: motor drivers' current loops); PAL Talos' harmonic drives have no backlash to speak of and a 1 kHz
#: EtherCAT loop (Stasse et al., "TALOS: A new humanoid research platform targeted for industrial
#: applications", Humanoids 2017). Coulomb friction scales with the robot's median leg effort (the
#: NAO's 0.02-0.06 N m is 1-2 % of its 3 N m leg motors); everything else is the NAO's "real" profile.
ACTUATOR_CLASS: dict[str, dict[str, Range]] = {
    "g1": {"latency_s": (0.015, 0.030), "backlash_rad": (0.0003, 0.001)},
    "talos": {"latency_s": (0.003, 0.008), "backlash_rad": (0.0, 0.0003)},
}
#: The NAO's median leg effort [N m] (``robots.nao``), the reference of the friction scaling.
NAO_LEG_EFFORT = 3.023


def real_profile_for(robot) -> RealProfile:
    """The "real" profile scaled to ``robot``'s actuator class (:data:`ACTUATOR_CLASS`); the NAO's
    own profile for the NAO.

    Args:
        robot: a ``robots.RobotModel``.
    """
    base = PROFILES["real"]
    if robot.name not in ACTUATOR_CLASS:
        return base
    legs = robot.joint_index(robot.groups["legs"])
    k = float(np.median(robot.effort[legs])) / NAO_LEG_EFFORT
    lo, hi = base.coulomb_friction_nm
    return dataclasses.replace(base, name="real", coulomb_friction_nm=(lo * k, hi * k), **ACTUATOR_CLASS[robot.name])


def get_profile(profile: str | dict | RealProfile, robot=None) -> RealProfile:
    """A profile by name (``"none"``, ``"real"``, ``"real-flat"``, ``"real-ground"``), from a dict of
    ranges, or passed through.

    Args:
        robot: the ``robots.RobotModel`` the profile is for; ``"real"`` and ``"real-flat"`` are then scaled to its
            actuators (:func:`real_profile_for`). None: the NAO's.

    Raises:
        ValueError: unknown profile name, or invalid ranges.
    """
    if isinstance(profile, RealProfile):
        return profile
    if isinstance(profile, dict):
        return RealProfile.from_dict(profile)
    if profile not in PROFILES:
        raise ValueError(f"unknown profile {profile!r}; known profiles: {', '.join(PROFILES)}")
    if profile in ("real", "real-flat") and robot is not None:
        scaled = real_profile_for(robot)
        return scaled if profile == "real" else _on_flat_ground(scaled)
    return PROFILES[profile]


@dataclass(frozen=True)
class Stochasticity:
    """Per-step randomness of the real world within an episode, apart from the per-episode effects.

    The effects of a :class:`RealProfile` are drawn once per episode; within an episode only the sensors
    are noisy. A level ``L >= 0`` adds two processes the physics draws while the robot walks, from a
    stream of their own (the episode seed's, or ``reset(options={"stochastic_seed": s})``):

    ==================  =============================================  ============================
    process             draw                                           stands for
    ==================  =============================================  ============================
    servo torque noise  per control step and joint, ``N(0, (0.03 L        current ripple and gear
                        tau_max)^2)`` [N m] added to the PD torque     friction that vary per step
                        (held over the control step's physics steps)
    touchdown friction  at each touchdown of a foot, its friction      turf: grip that differs at
                        ``mu * exp(N(0, (0.2 L)^2))``, clipped to      every footstep
                        [0.3, 2.0]
    touchdown softness  at each touchdown, the contact stiffness       foam under the turf: a sole
                        ``k = 10^U(6 - 0.75 L, 6)`` [N/m], damping     sinks 0.05 mm to 5 cm,
                        ``2 sqrt(k m / 2)`` [N s/m] (m the robot's     different at every step
                        mass: critically damped on one foot)
    ==================  =============================================  ============================

    Level 0 draws nothing: the real world as it is, bit for bit. The NAO's initial gait θ0 walks 7.5 s
    on level 0-3 in most episodes (``docs/concepts/worlds.md`` has the measured fall rates).
    The NAO walking on "foam under turf", where the forces acting on the foot differ at every step, is
    the setting of Desai et al., "Stochastic Grounded Action Transformation for Robot Learning in
    Simulation" (IROS 2020), Sec. V.

    Raises:
        ValueError: a negative or non-finite level.
    """

    level: float = 0.0

    #: Servo torque noise per level, as a fraction of each joint's torque limit (std).
    TORQUE = 0.03
    #: Log-normal spread of the foot friction drawn at each touchdown, per level.
    FRICTION = 0.2
    #: Decades of contact stiffness below 10^6 N/m that a touchdown draws from, per level.
    SOFTNESS = 0.75

    def __post_init__(self) -> None:
        if not (np.isfinite(self.level) and self.level >= 0):
            raise ValueError(f"stochasticity must be a number >= 0, got {self.level!r}")

    @property
    def active(self) -> bool:
        return self.level > 0

    def torque_noise(self, rng: np.random.Generator, tau_max: np.ndarray) -> np.ndarray:
        """One control step's torque noise per joint [N m], shape of ``tau_max``."""
        return rng.normal(0.0, 1.0, tau_max.shape) * (self.TORQUE * self.level) * tau_max

    def touchdown(self, rng: np.random.Generator, friction: float, mass: float) -> dict:
        """One touchdown's contact: ``{"lateralFriction", "contactStiffness", "contactDamping"}``
        (``pybullet.changeDynamics`` keywords) for a foot of nominal friction ``friction`` on a robot
        of ``mass`` [kg]."""
        mu = float(np.clip(friction * np.exp(rng.normal(0.0, self.FRICTION * self.level)), 0.3, 2.0))
        k = 10.0 ** rng.uniform(6.0 - self.SOFTNESS * self.level, 6.0)
        return {"lateralFriction": mu, "contactStiffness": float(k),
                "contactDamping": float(2.0 * np.sqrt(k * mass / 2.0))}
