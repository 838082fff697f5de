"""The table of effect kinds of the strangers' world, their draw ranges and their targets.

Every kind is an :class:`EffectKind`: a name, what it targets (``"joint"``: one to three actuated
joints; ``"link"``: one link other than the root; ``"root"``: the torso; ``"global"``), a paragraph of
physics with its literature source, its headline parameter (the value a trial is scored on, the
``values`` entry of a hidden effect) and its other parameters (the ``params`` entry), each with its
unit, the range a trial draws it from and the wider range the world accepts.

A hidden effect is a dict in the blind referee's shape, plus the other parameters::

    {"family": "friction_stribeck", "targets": ["LKneePitch"], "values": [0.09],
     "params": [{"stiction_ratio": 1.6, "stribeck_speed": 0.1, "stribeck_exponent": 1.2, "viscous": 0.05}]}

``targets`` are joint names, link names, ``[robot.root]`` or ``[None]`` (global); ``values`` one
float per target; ``params`` one dict per target (missing keys take the parameter's default; may be
left out altogether). Parameters drawn "x effort" or "x velocity" are given to the world in absolute
units (N m, rad/s); the range is the joint's URDF effort or velocity times the listed numbers.

=========================  ======  =========================================  =====================
kind                       target  headline (draw range)                      others (draw range)
=========================  ======  =========================================  =====================
servo_gain                 joint   scale of kp, kd and torque ceiling 0.6-0.85
kp_error                   joint   kp scale 0.6-0.85 or 1.2-1.5
kd_error                   joint   kd scale 0.3-0.7 or 1.5-3 (log-uniform)
backlash_motor             joint   gap (full width) 6-14 mrad
backlash_link              joint   gap (full width) 6-14 mrad
torque_saturation          joint   torque ceiling 0.45-0.70 x effort
torque_speed               joint   no-load speed 0.7-1.2 x URDF velocity
friction_coulomb_viscous   joint   Coulomb 0.02-0.06 x effort [N m]           viscous 0.01-0.04 x effort
friction_stribeck          joint   Coulomb 0.02-0.06 x effort [N m]           stiction ratio 1.3-2, Stribeck
                                                                              speed 0.05-0.3 rad/s, exponent
                                                                              0.5-2, viscous 0.01-0.04 x effort
encoder_offset             joint   offset +-3-15 mrad (servo and log)
readout_offset             joint   offset +-3-15 mrad (log only)
com_offset                 link    CoM shift 1-3 cm                           direction: unit vector
inertia_scale              link    rotational inertia scale 1.5-3
torso_mass                 root    mass scale 1.1-1.25 (floating base)
torso_com                  root    CoM shift 1-3 cm (floating base)           direction: horizontal
latency_lowpass            global  lag time constant 5-20 ms                  transport delay 2-10 ms
foot_friction              global  foot-ground friction coefficient 0.25-0.5 (floating base)
uneven_ground              global  RMS height 1.5-4 mm (floating base)        wavelength 0.3-0.6 m
=========================  ======  =========================================  =====================

Which joints and links a kind is drawn on (:func:`eligible_targets`): never the HipYawPitch pair (one
motor drives both through a gear constraint, so a per-joint effect is not defined there); joints where
the effect is observable (torque_saturation: the PD asks for 0.7 x effort at a 0.2 rad tracking error;
torque_speed: for 0.5 x effort) and where the explicit 1 kHz loop stays stable over the whole drawn
range: the coupled :func:`stability_index` of the hanging robot with the effect at the top of its range
on that joint stays within :data:`STABILITY_BUDGET` (kd_error, kp_error, backlash_motor, the two
frictions; the frictions also need a presliding deflection of at most 5 mrad). A draw on several joints
is checked again as a whole (:func:`draw_effect`). Links: at least 0.1 kg below a single-motor joint
(inertia_scale: the link's own rotational inertia about its joint axis at least 5 % of that joint's
mass-matrix diagonal, else a x3 change does not show).

Observability caveats: encoder_offset leaves a hanging robot's log nearly unchanged (the servo holds the
link at q* - b and the log reads about q*; only the gravity torque at the shifted angle shows, < 0.1 b):
it shows in floating-base logs (posture, IMU). The backlash forms show a dead zone on reversals only where
something on the link side resists motion (gear friction, a load that changes sign); under a one-sided
gravity load the link rests on one face (an offset of half the gap for backlash_motor; hidden from the
encoder for backlash_link).
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
from dataclasses import dataclass, field

import numpy as np

from common.defaults import PHYSICS_DT

# ------------------------------------------------------------------------------------------ constants
#: Links lighter than this [kg] are not drawn for inertial effects (the blind referee's threshold).
MIN_LINK_MASS = 0.1
#: Share of a joint's mass-matrix diagonal the link's own rotational inertia must reach (inertia_scale).
MIN_INERTIA_SHARE = 0.05
#: The tracking error [rad] at which a torque ceiling must bind for the ceiling to be drawn on a joint.
CEILING_ERROR = 0.2
#: Stability budget of the explicit PD at the physics step: a draw is allowed while the coupled
#: :func:`stability_index` (4: unstable; the nominal NAO gains: 1.93) stays <= this. Measured: 3.5 on
#: ElbowYaw (friction at the top of its range) made the collinear WristYaw chatter at 87 rad/s.
STABILITY_BUDGET = 3.0
#: Gear contact of the motor-side backlash: stiffness [N m/rad] as a multiple of the joint's kp, and
#: the damping ratio of the contact against the joint's effective inertia.
CONTACT_STIFFNESS_RATIO = 10.0
CONTACT_DAMPING_RATIO = 0.1
#: Presliding deflection [rad] of the elasto-plastic friction at the breakaway torque (bristle stiffness
#: sigma0 = tau_s / PRESLIDING; lowered where the stability budget asks, up to MAX_PRESLIDING).
PRESLIDING = 0.002
MAX_PRESLIDING = 0.005
#: Redraws of a several-joint draw whose coupled loop is over the budget (draw_effect).
MAX_REDRAWS = 50
#: The pose the effective inertias are computed at (the worlds' initial pose).
INERTIA_POSE = "crouch"


# ------------------------------------------------------------------------------------------ the table
@dataclass(frozen=True)
class Parameter:
    """One parameter of an effect kind.

    Attributes:
        name: its key (in ``params``; the headline parameter is ``values`` instead).
        unit: SI unit of the value the world takes.
        draw: the bands a trial draws from, ``((low, high), ...)``; a band is chosen uniformly, then a
            value uniformly (log-uniformly if ``log``) inside it; times the joint's effort or velocity if
            ``scale`` says so; with a random sign if ``signed``.
        valid: the range the world accepts (same scaling; a signed parameter: its magnitude).
        default: the value a missing key takes (absolute units; None for a scaled parameter: the middle of
            the draw range times the scale).
        scale: None, ``"effort"`` (the joint's URDF effort [N m]) or ``"velocity"`` (its URDF velocity
            [rad/s]).
        vector: 3 for a unit direction vector (``draw``/``valid`` unused; drawn on the sphere, or on the
            horizontal circle if ``horizontal``).
    """

    name: str
    unit: str
    draw: tuple[tuple[float, float], ...] = ()
    valid: tuple[float, float] = (-math.inf, math.inf)
    default: float | None = None
    scale: str | None = None
    log: bool = False
    signed: bool = False
    vector: int = 0
    horizontal: bool = False


@dataclass(frozen=True)
class EffectKind:
    """One kind of hidden effect (module docstring).

    Attributes:
        name: the kind's name (the ``family`` of a hidden effect).
        target: ``"joint"``, ``"link"``, ``"root"`` or ``"global"``.
        description: the physics and how the world implements it.
        source: literature the form comes from.
        value: the headline parameter; ``extra``: the others.
        floating_only: True if it acts only with a floating base (the world refuses it on a fixed base).
        max_targets: how many targets a draw picks at most (joints: 1 to 3).
    """

    name: str
    target: str
    description: str
    source: str
    value: Parameter
    extra: tuple[Parameter, ...] = ()
    floating_only: bool = False
    max_targets: int = 1

    @property
    def parameters(self) -> tuple[Parameter, ...]:
        return (self.value,) + self.extra


_GAP = Parameter("gap", "rad", ((0.006, 0.014),), (0.0, 0.04))
_OFFSET = Parameter("offset", "rad", ((0.003, 0.015),), (0.0, 0.05), signed=True)
_COULOMB = Parameter("coulomb", "N m", ((0.02, 0.06),), (0.0, 0.3), scale="effort")
_VISCOUS = Parameter("viscous", "N m s/rad", ((0.01, 0.04),), (0.0, 0.1), default=0.0, scale="effort")
_SHIFT = Parameter("distance", "m", ((0.01, 0.03),), (0.0, 0.05))

KINDS: dict[str, EffectKind] = {k.name: k for k in (
    EffectKind(
        "servo_gain", "joint",
        "Torque-constant (or supply-voltage) error of the servo: the motor gives less torque per unit of "
        "commanded current than the controller assumes, so the whole PD output and the driver's torque "
        "ceiling shrink by the same factor s: tau = s * clip(kp e - kd qdot, +-effort).",
        "DC motor torque tau = K_t i (A. Hughes, B. Drury, Electric Motors and Drives, 5th ed., Newnes 2019, "
        "ch. 3); NAO servo boards run a current loop under the position loop (D. Gouaillier et al., "
        "\"Mechatronic design of NAO humanoid\", ICRA 2009).",
        Parameter("scale", "-", ((0.6, 0.85),), (0.3, 1.5)), max_targets=3),
    EffectKind(
        "kp_error", "joint",
        "Proportional gain of the servo off its nominal value (a firmware stiffness setting, a gain "
        "scaled in encoder counts): tau = clip(s kp e - kd qdot, +-effort).",
        "PD position servo (G. F. Franklin, J. D. Powell, A. Emami-Naeini, Feedback Control of Dynamic "
        "Systems, 8th ed., Pearson 2019, ch. 4).",
        Parameter("scale", "-", ((0.6, 0.85), (1.2, 1.5)), (0.3, 2.0)), max_targets=3),
    EffectKind(
        "kd_error", "joint",
        "Derivative gain alone off its nominal value (a velocity estimate scaled wrong, a D gain set apart "
        "from P): tau = clip(kp e - s kd qdot, +-effort). Drawn log-uniformly in a band below or above "
        "nominal, only on joints whose explicit damping stays stable at 3 x kd.",
        "PD position servo (Franklin, Powell, Emami-Naeini 2019, ch. 4).",
        Parameter("scale", "-", ((0.3, 0.7), (1.5, 3.0)), (0.1, 3.0), log=True), max_targets=3),
    EffectKind(
        "backlash_motor", "joint",
        "Gear play on the motor side of the joint encoder, in a semi-closed-loop servo: a massless motor "
        "under the servo's PD on the motor angle theta drives the link through a dead zone of full width "
        "`gap`; engaged, the teeth are a stiff spring-damper (stiffness 10 kp, damping ratio 0.1 against "
        "the joint's effective inertia) that can only push. The motor is solved by backward Euler each "
        "physics step (kp (q* - theta) - kd thetadot = contact torque, torque ceilings on the motor). The "
        "logged joint angle is the link's (an output-shaft sensor): a hanging link rests on one face of "
        "the gap, and on a reversal the link waits while the motor crosses the gap.",
        "Dead-zone (gear play) model with contact stiffness: M. Nordin, J. Galic, P.-O. Gutman, \"New "
        "models for backlash and gear play\", Int. J. Adaptive Control and Signal Processing 11(1), 1997; "
        "semi-closed-loop position control with load-side play: G. Ellis, Control System Design Guide, "
        "4th ed., 2012, ch. 16.",
        _GAP, max_targets=3),
    EffectKind(
        "backlash_link", "joint",
        "Gear play on the link side of the joint encoder: the only encoder sits on the motor shaft, so the "
        "servo's PD and the logged angle both read the motor angle theta while the link lags within the "
        "gap. Rigid teeth (the play operator): a massless motor under PD moves freely in the gap "
        "(kp (q* - theta) = kd thetadot, backward Euler) and, at a face, moves with the link and passes "
        "the PD torque kp (q* - theta) - kd qdot if it pushes, nothing if it would pull. The log shows the "
        "motor crossing the gap quickly at a reversal and a link hidden from the encoder.",
        "Backlash as the play (hysteresis) operator: G. Tao, P. V. Kokotovic, \"Adaptive control of "
        "systems with backlash\", Automatica 29(2), 1993; M. Nordin, P.-O. Gutman, \"Controlling "
        "mechanical systems with backlash - a survey\", Automatica 38(10), 2002.",
        _GAP, max_targets=3),
    EffectKind(
        "torque_saturation", "joint",
        "The servo driver's current limit (thermal protection, a firmware ceiling) caps the output torque "
        "below the URDF effort: |tau| <= s * effort. Drawn on joints whose PD asks for the ceiling at a "
        "0.2 rad tracking error.",
        "Current-limited motor drive (Hughes, Drury 2019, ch. 4); NAO joint 'stiffness' as a torque "
        "ceiling (Aldebaran NAOqi ALMotion documentation, stiffness control).",
        Parameter("scale", "-", ((0.45, 0.70),), (0.05, 1.0)), max_targets=3),
    EffectKind(
        "torque_speed", "joint",
        "Back-EMF limit of a DC motor on a bounded supply: the torque available falls linearly with speed, "
        "|tau| <= tau_stall (1 - |omega| / omega_noload), clipped at 0, with tau_stall the URDF effort and "
        "omega the joint speed, when torque and speed share a sign (motoring); a braking torque is bounded "
        "by the effort alone (the back-EMF drives braking current: the four-quadrant DC-motor line, as "
        "IsaacLab's DCMotor clips it). Applying the envelope to braking too would leave a joint above "
        "omega_noload with no torque to stop it, which no DC motor does. The URDF velocity of the NAO "
        "joints is about the no-load motor speed over the reduction ratio; a lower battery voltage or a "
        "hot winding lowers it.",
        "DC motor torque-speed line (Hughes, Drury 2019, ch. 3); NAO motor and reduction data (Aldebaran "
        "NAO H25 motors datasheet); as an actuator model: IsaacLab ``DCMotor`` (torque-speed saturation).",
        Parameter("no_load_speed", "rad/s", ((0.7, 1.2),), (0.2, 5.0), scale="velocity"), max_targets=3),
    EffectKind(
        "friction_coulomb_viscous", "joint",
        "Joint friction, BAM's model M1: tau_f = -tau_c sign(omega) - b omega. Stiction is handled by a "
        "single-state elasto-plastic (bristle) model: a deflection z grows with the joint's motion and is "
        "capped at tau_c / sigma0, tau_f = -sigma0 z - b omega; at rest the friction holds any torque "
        "below tau_c after a presliding deflection of 2 mrad (up to 5 mrad on light joints, where the "
        "stability budget lowers sigma0).",
        "Coulomb-viscous model M1 of M. Duclusaud, G. Passault, V. Padois, O. Ly, \"Extended friction "
        "models for the physics simulation of servo actuators\", ICRA 2025 (arXiv:2410.08650; Rhoban's "
        "BAM, Better Actuator Models); elasto-plastic friction: P. Dupont, V. Hayward, B. Armstrong, F. "
        "Altpeter, \"Single state elastoplastic friction models\", IEEE TAC 47(5), 2002.",
        _COULOMB, (_VISCOUS,), max_targets=3),
    EffectKind(
        "friction_stribeck", "joint",
        "Joint friction, BAM's model M2 (Stribeck): tau_f = -(tau_c + (tau_s - tau_c) exp(-(|omega| / "
        "omega_s)^delta)) sign(omega) - b omega, with tau_s = stiction_ratio * tau_c; the breakaway "
        "torque tau_s at rest falls to tau_c above the Stribeck speed. Implemented by the same "
        "elasto-plastic bristle as friction_coulomb_viscous, its cap following the Stribeck curve at the "
        "joint's speed (the LuGre steady state).",
        "Stribeck model M2 of Duclusaud et al., ICRA 2025 (BAM); LuGre: C. Canudas de Wit, H. Olsson, "
        "K. J. Astrom, P. Lischinsky, \"A new model for control of systems with friction\", IEEE TAC 40(3), "
        "1995; elasto-plastic: Dupont et al. 2002.",
        _COULOMB,
        (Parameter("stiction_ratio", "-", ((1.3, 2.0),), (1.0, 3.0), default=1.5),
         Parameter("stribeck_speed", "rad/s", ((0.05, 0.3),), (0.005, 2.0), default=0.1),
         Parameter("stribeck_exponent", "-", ((0.5, 2.0),), (0.3, 3.0), default=1.0),
         _VISCOUS), max_targets=3),
    EffectKind(
        "encoder_offset", "joint",
        "Calibration offset of the joint encoder: the servo and the log read q + b, so the servo holds the "
        "link at q* - b and the log reads about q*; seen through gravity torques on a hanging robot and "
        "through the posture of a standing one.",
        "Joint-offset calibration (B. Siciliano, O. Khatib (eds.), Springer Handbook of Robotics, 2nd ed., "
        "2016, ch. 9, model identification: kinematic calibration).",
        _OFFSET, max_targets=3),
    EffectKind(
        "readout_offset", "joint",
        "Offset of the logged joint angle only (a zero applied in the logging path, not in the servo's "
        "loop): the servo holds the link at q*, the log reads q + b.",
        "Sensor bias on a measurement channel (Siciliano, Khatib 2016, ch. 9).",
        _OFFSET, max_targets=3),
    EffectKind(
        "com_offset", "link",
        "The link's centre of mass moved by `distance` along `direction` (a unit vector in the link "
        "frame) from the URDF value: cable routing, a replaced part. Changes the static torque under "
        "gravity at the joints above the link and its dynamic coupling. Written into the URDF the world "
        "loads (the inertia about the CoM unchanged).",
        "Rigid-body inertial parameters (R. Featherstone, Rigid Body Dynamics Algorithms, Springer 2008, "
        "ch. 2); NAO link inertials: ros-naoqi V50 URDF.",
        _SHIFT, (Parameter("direction", "-", vector=3),)),
    EffectKind(
        "inertia_scale", "link",
        "The link's rotational inertia about its centre of mass scaled by s (mass and CoM unchanged): a "
        "mass distribution further from the CoM than the URDF's (all six tensor entries scaled, so the "
        "tensor stays physical). Drawn on links whose own inertia is at least 5 % of their joint's "
        "mass-matrix diagonal.",
        "Rigid-body inertial parameters (Featherstone 2008, ch. 2).",
        Parameter("scale", "-", ((1.5, 3.0),), (0.3, 5.0))),
    EffectKind(
        "torso_mass", "root",
        "Floating base: the torso (root) mass scaled by s, its inertia with it (a denser torso: battery, "
        "added electronics); shifts the weight on the feet and the whole-body CoM. Bullet ignores a fixed "
        "base's mass, so this kind acts with a floating base only.",
        "Floating-base dynamics (Featherstone 2008, ch. 9).",
        Parameter("scale", "-", ((1.1, 1.25),), (0.5, 2.0)), floating_only=True),
    EffectKind(
        "torso_com", "root",
        "Floating base: the torso's centre of mass moved by `distance` along `direction` (a unit vector in "
        "the torso frame, drawn horizontal): a shifted battery or payload; moves the CoP of a standing "
        "robot and the posture its balance ends in.",
        "Floating-base dynamics (Featherstone 2008, ch. 9).",
        _SHIFT, (Parameter("direction", "-", vector=3, horizontal=True),), floating_only=True),
    EffectKind(
        "latency_lowpass", "global",
        "Command path of every joint: a transport delay d (whole physics steps) followed by a first-order "
        "low-pass of time constant T (exact discretisation, y += (1 - exp(-dt / T)) (u - y) at each 1 ms "
        "step) in front of the PD: bus transfer plus the servo's command smoothing. Not a pure delay: "
        "the phase lag grows as atan(omega T) and the amplitude falls above 1 / (2 pi T); at low "
        "frequency it looks like a delay of d + T.",
        "First-order lag plus dead time (FOPDT) model (D. E. Seborg, T. F. Edgar, D. A. Mellichamp, F. J. "
        "Doyle, Process Dynamics and Control, 4th ed., Wiley 2016, ch. 6); NAO DCM cycle and servo command "
        "interpolation (Aldebaran NAOqi DCM documentation).",
        Parameter("time_constant", "s", ((0.005, 0.020),), (0.0005, 0.05)),
        (Parameter("delay", "s", ((0.002, 0.010),), (0.0, 0.05), default=0.0),)),
    EffectKind(
        "foot_friction", "global",
        "Coulomb friction coefficient of the foot-ground contact (polished floor, worn soles), set on both "
        "feet (Bullet multiplies the two bodies' coefficients; the ground's is 1). Floating base only.",
        "Coulomb friction cone at contacts (Siciliano, Khatib 2016, ch. 37); Bullet friction combination "
        "(btManifoldResult::calculateCombinedFriction).",
        Parameter("mu", "-", ((0.25, 0.5),), (0.05, 1.5)), floating_only=True),
    EffectKind(
        "uneven_ground", "global",
        "Uneven ground: a fresh fractal Perlin-noise heightfield per episode (drawn from the episode seed's "
        "terrain stream) of RMS height Sq = `rms_height`, coarsest wavelength `wavelength`, three octaves, "
        "no flat start pad (benchmarks.strangers.ground): the robot stands on it from the start. The ranges "
        "keep the RMS slope at 0.025-0.05 (the project's lumpy real ground: about 0.03); Sq 4-6 mm at a "
        "0.2 m wavelength (slopes near 0.1) topples even a standing robot. Floating base only.",
        "K. Perlin, \"Improving Noise\", SIGGRAPH 2002; fractal sums: F. K. Musgrave in Ebert et al., "
        "Texturing & Modeling, 3rd ed., 2003; Sq: ISO 25178-2.",
        Parameter("rms_height", "m", ((0.0015, 0.004),), (0.0, 0.02)),
        (Parameter("wavelength", "m", ((0.3, 0.6),), (0.16, 2.0), default=0.45),), floating_only=True),
)}

FIXED_BASE_KINDS = tuple(k for k, v in KINDS.items() if not v.floating_only)
FLOATING_ONLY_KINDS = tuple(k for k, v in KINDS.items() if v.floating_only)
#: Kinds that cannot share a joint (one transmission, one friction model, one encoder zero per joint).
EXCLUSIVE = ({"backlash_motor", "backlash_link"}, {"friction_coulomb_viscous", "friction_stribeck"})


# ------------------------------------------------------------------------------------------ inertia
@contextlib.contextmanager
def _silent():
    """Silence C-level stdout and stderr (Bullet prints build time and inverse-dynamics warnings)."""
    saved = []
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (AttributeError, OSError, ValueError):
            pass
    try:
        for fd in (1, 2):
            try:
                saved.append((fd, os.dup(fd)))
            except OSError:
                continue
            with open(os.devnull, "w") as null:
                os.dup2(null.fileno(), fd)
        yield
    finally:
        for fd, s in saved:
            os.dup2(s, fd)
            os.close(s)


_INERTIA: dict = {}
_BY_ID: dict = {}  # (id(robot), dt) -> (robot, key): skips building the URDF text


def joint_inertia(robot, physics_dt: float = PHYSICS_DT) -> dict:
    """The hanging robot's (base fixed) joint-space inertia at the pose :data:`INERTIA_POSE`, from
    Bullet's mass matrix (``calculateMassMatrix``, PyBullet Quickstart Guide) of the URDF the worlds load.
    Cached per robot description.

    Returns:
        ``{"minv": (n, n) inverse mass matrix [1/(kg m^2)] in ``robot.joint_names`` order, "effective":
        {joint: 1 / (M^-1)_ii}, "diagonal": {joint: M_ii}}`` (inertias [kg m^2]; the effective inertia is
        what a torque at that joint alone accelerates, the other joints free).
    """
    hit = _BY_ID.get((id(robot), physics_dt))
    if hit is not None and hit[0] is robot:
        return _INERTIA[hit[1]]
    key = (robot.name, robot.urdf(), physics_dt)
    _BY_ID[(id(robot), physics_dt)] = (robot, key)
    if key not in _INERTIA:
        with _silent():
            import pybullet
            from pybullet_utils.bullet_client import BulletClient

            client = BulletClient(connection_mode=pybullet.DIRECT)
            try:
                flags = pybullet.URDF_USE_INERTIA_FROM_FILE | pybullet.URDF_MAINTAIN_LINK_ORDER
                body = client.loadURDF(robot.write_urdf(), [0, 0, robot.hang_height], useFixedBase=True, flags=flags)
                names = {client.getJointInfo(body, i)[1].decode(): i for i in range(client.getNumJoints(body))}
                pose = robot.pose(INERTIA_POSE) if INERTIA_POSE in robot.poses else np.zeros(len(robot.joint_names))
                q = np.zeros(client.getNumJoints(body))
                for n, v in zip(robot.joint_names, pose):
                    q[names[n]] = v
                M = np.array(client.calculateMassMatrix(body, q.tolist()))
            finally:
                client.disconnect()
        idx = [names[n] for n in robot.joint_names]
        Minv = np.linalg.inv(M)[np.ix_(idx, idx)]
        _INERTIA[key] = {"minv": Minv,
                         "effective": {n: 1.0 / Minv[k, k] for k, n in enumerate(robot.joint_names)},
                         "diagonal": {n: M[i, i] for n, i in zip(robot.joint_names, idx)}}
    return _INERTIA[key]


def stability_index(robot, stiffness: np.ndarray, damping: np.ndarray, dt: float = PHYSICS_DT) -> float:
    """The largest eigenvalue of M^-1 (dt^2 K + 2 dt C) (dimensionless) for the hanging robot under joint
    stiffnesses ``K`` [N m/rad] and dampings ``C`` [N m s/rad] (shape (n,), ``robot.joint_names`` order)
    applied explicitly at the step ``dt`` [s], M the joint-space mass matrix (:func:`joint_inertia`).

    For one degree of freedom, symplectic Euler (Bullet's integrator) on I qddot = -K q - C qdot is stable
    iff dt^2 K / I + 2 dt C / I < 4 (the roots of z^2 - (2 - a - k) z + (1 - a) lie in the unit circle iff
    0 < a < 2 and k < 4 - 2a); this is its coupled form. The nominal NAO gains give 1.93.
    """
    Minv = joint_inertia(robot, dt)["minv"]
    D = dt * dt * np.asarray(stiffness, dtype=float) + 2.0 * dt * np.asarray(damping, dtype=float)
    r = np.sqrt(np.maximum(D, 0.0))  # M^-1 D has the eigenvalues of the symmetric D^1/2 M^-1 D^1/2
    return float(np.linalg.eigvalsh(r[:, None] * Minv * r[None, :])[-1])


def contact_parameters(robot, joint: str) -> tuple[float, float]:
    """Gear-contact stiffness [N m/rad] and damping [N m s/rad] of the motor-side backlash on ``joint``:
    :data:`CONTACT_STIFFNESS_RATIO` x kp, and damping ratio :data:`CONTACT_DAMPING_RATIO` against the
    joint's effective inertia (:func:`joint_inertia`)."""
    j = robot.joint_names.index(joint)
    kc = CONTACT_STIFFNESS_RATIO * float(robot.kp[j])
    I = joint_inertia(robot)["effective"][joint]
    return kc, 2.0 * CONTACT_DAMPING_RATIO * math.sqrt(kc * I)


def contact_stiffness_seen(robot, joint: str, kp: float, kd: float, dt: float = PHYSICS_DT) -> tuple[float, float]:
    """Stiffness [N m/rad] and damping [N m s/rad] the link of a motor-side backlash on ``joint`` sees
    through the engaged contact and the massless motor (servo gains ``kp``, ``kd``), from the backward
    Euler solve: K = kc A / D, C = bc A / D with A = kp + kd / dt, D = A + kc + bc / dt."""
    kc, bc = contact_parameters(robot, joint)
    A = kp + kd / dt
    D = A + kc + bc / dt
    return kc * A / D, bc * A / D


def bristle_stiffness(robot, joint: str, stiction: float, stiffness: np.ndarray, damping: np.ndarray,
                      dt: float = PHYSICS_DT) -> float:
    """Bristle stiffness sigma0 [N m/rad] of the elasto-plastic friction on ``joint`` with breakaway
    torque ``stiction`` [N m]: ``stiction /`` :data:`PRESLIDING`, lowered (bisection) so that the
    :func:`stability_index` of the joint stiffnesses ``stiffness`` plus sigma0 on ``joint`` and the
    dampings ``damping`` (the viscous friction included) stays within :data:`STABILITY_BUDGET` (the
    presliding deflection grows). Shapes (n,), ``robot.joint_names`` order."""
    j = robot.joint_names.index(joint)
    want = stiction / PRESLIDING if stiction > 0 else 0.0

    def ok(s0: float) -> bool:
        k = np.array(stiffness, dtype=float)
        k[j] += s0
        return stability_index(robot, k, damping, dt) <= STABILITY_BUDGET

    if ok(want):
        return float(max(want, 1e-9))
    lo, hi = 0.0, want
    for _ in range(20):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ok(mid) else (lo, mid)
    return float(max(lo, 1e-9))


# ------------------------------------------------------------------------------------------ targets
def plain_joints(robot) -> tuple[str, ...]:
    """Actuated joints that drive one link each: the actuated joints minus the mimic pairs (the NAO's
    HipYawPitch: one motor, two outputs coupled by a gear constraint)."""
    coupled = set(robot.mimic) | set(robot.mimic.values())
    return tuple(n for n in robot.actuated_joint_names if n not in coupled)


def _scaled(p: Parameter, robot, joint: str | None) -> float:
    if p.scale is None:
        return 1.0
    if joint is None:
        raise ValueError(f"parameter {p.name!r} is scaled by a joint's {p.scale} but has no joint")
    j = robot.joint_names.index(joint)
    return float(robot.effort[j] if p.scale == "effort" else robot.velocity[j])


def _top(p: Parameter) -> float:
    return max(hi for _, hi in p.draw)


_ELIGIBLE: dict = {}


def eligible_targets(kind: str, robot) -> tuple:
    """The targets a draw of ``kind`` picks among, for ``robot`` (module docstring; ``[robot.root]`` or
    ``[None]`` for root and global kinds). Cached per robot description.

    Raises:
        ValueError: unknown kind.
    """
    _kind(kind)
    key = (kind, robot.name, robot.urdf())
    if key not in _ELIGIBLE:
        _ELIGIBLE[key] = _eligible(kind, robot)
    return _ELIGIBLE[key]


def _eligible(kind: str, robot) -> tuple:
    spec = KINDS[kind]
    if spec.target == "global":
        return (None,)
    if spec.target == "root":
        return (robot.root,)
    if spec.target == "link":
        plain = set(plain_joints(robot))
        links = [j for j in robot.joints if j.name in plain and j.inertial.mass >= MIN_LINK_MASS]
        if kind == "inertia_scale":
            inertia = joint_inertia(robot)
            keep = []
            for j in links:
                ixx, iyy, izz, ixy, ixz, iyz = j.inertial.inertia
                T = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
                a = np.array(j.axis, dtype=float) / np.linalg.norm(j.axis)
                if a @ T @ a >= MIN_INERTIA_SHARE * inertia["diagonal"][j.name]:
                    keep.append(j)
            links = keep
        return tuple(j.child for j in links)
    out = []
    for n in plain_joints(robot):
        j = robot.joint_names.index(n)
        kp, eff = float(robot.kp[j]), float(robot.effort[j])
        if kind == "torque_saturation" and kp * CEILING_ERROR < _top(spec.value) * eff:
            continue
        if kind == "torque_speed" and kp * CEILING_ERROR < 0.5 * eff:
            continue
        if kind in ("kd_error", "kp_error", "backlash_motor", "friction_coulomb_viscous", "friction_stribeck"):
            try:
                compile_effects(robot, validate_hidden([corner_effect(kind, robot, "high", [n])], robot, True),
                                limit=STABILITY_BUDGET, presliding=MAX_PRESLIDING)
            except ValueError:
                continue
        out.append(n)
    return tuple(out)


# ------------------------------------------------------------------------------------------ drawing
def _kind(kind) -> EffectKind:
    if kind not in KINDS:
        raise ValueError(f"unknown effect kind {kind!r}; known: {', '.join(KINDS)}")
    return KINDS[kind]


def _draw_param(p: Parameter, rng: np.random.Generator, robot, joint: str | None):
    if p.vector:
        if p.horizontal:
            a = rng.uniform(0.0, 2.0 * math.pi)
            return [math.cos(a), math.sin(a), 0.0]
        v = rng.standard_normal(3)
        return (v / np.linalg.norm(v)).tolist()
    lo, hi = p.draw[int(rng.integers(len(p.draw)))] if len(p.draw) > 1 else p.draw[0]
    x = math.exp(rng.uniform(math.log(lo), math.log(hi))) if p.log else rng.uniform(lo, hi)
    if p.name == "delay":  # the transport delay acts in whole physics steps
        x = float(np.rint(x / PHYSICS_DT)) * PHYSICS_DT
    if p.signed:
        x *= float(rng.choice([-1.0, 1.0]))
    return float(x * _scaled(p, robot, joint))


def draw_effect(kind: str, rng: np.random.Generator, robot) -> dict:
    """One hidden effect of ``kind`` drawn from its ranges (module docstring's table).

    Joint kinds pick 1 to ``max_targets`` distinct joints of :func:`eligible_targets` (the count first,
    then the joints, then each target's headline value and other parameters in table order); link kinds
    one link; root and global kinds their single target. A draw on several joints whose coupled loop
    exceeds :data:`STABILITY_BUDGET` (:func:`compile_effects`) is drawn again (other joints, new values)
    from the same Generator. Deterministic for a seeded Generator.

    Returns:
        ``{"family": kind, "targets": [...], "values": [float per target], "params": [dict per target]}``
        (``params`` holds every other parameter of the kind, absolute units; ``direction`` as a list of 3).

    Raises:
        ValueError: unknown kind, or no eligible target on ``robot``.
    """
    spec = _kind(kind)
    cands = list(eligible_targets(kind, robot))
    if not cands:
        raise ValueError(f"effect kind {kind!r} has no eligible target on robot {robot.name!r}")
    if spec.target == "joint":
        k = int(rng.integers(1, min(spec.max_targets, len(cands)) + 1))
        targets = [str(x) for x in rng.choice(cands, k, replace=False)]
    elif spec.target == "link":
        targets = [str(rng.choice(cands))]
    else:
        targets = cands
    for _ in range(MAX_REDRAWS):
        values, params = [], []
        for t in targets:
            joint = t if spec.target == "joint" else None
            values.append(_draw_param(spec.value, rng, robot, joint))
            params.append({p.name: _draw_param(p, rng, robot, joint) for p in spec.extra})
        effect = {"family": kind, "targets": targets, "values": values, "params": params}
        if spec.target != "joint" or len(targets) == 1:
            return effect
        try:  # several joints at once: the coupled loop must stay within the budget too
            compile_effects(robot, validate_hidden([effect], robot, True), limit=STABILITY_BUDGET,
                            presliding=MAX_PRESLIDING)
            return effect
        except ValueError:
            targets = [str(x) for x in rng.choice(cands, len(targets), replace=False)]
    raise ValueError(f"no stable draw of {kind!r} on {len(targets)} joints in {MAX_REDRAWS} tries")  # pragma: no cover


def corner_effect(kind: str, robot, corner: str, targets: list | None = None) -> dict:
    """An effect of ``kind`` at a corner of its draw range, for stability checks: every parameter at the
    low (``corner="low"``) or high (``"high"``) end of its draw bands (signed parameters: the magnitude,
    positive; directions: +x), on ``targets`` (default: every eligible target; link kinds: the first).

    Raises:
        ValueError: unknown kind or corner.
    """
    spec = _kind(kind)
    if corner not in ("low", "high"):
        raise ValueError(f"corner must be 'low' or 'high', got {corner!r}")
    if targets is None:
        targets = list(eligible_targets(kind, robot))
        if spec.target == "link":
            targets = targets[:1]

    def pick(p: Parameter, joint):
        if p.vector:
            return [1.0, 0.0, 0.0]
        x = min(lo for lo, _ in p.draw) if corner == "low" else _top(p)
        return float(x * _scaled(p, robot, joint))

    values, params = [], []
    for t in targets:
        joint = t if spec.target == "joint" else None
        values.append(pick(spec.value, joint))
        params.append({p.name: pick(p, joint) for p in spec.extra})
    return {"family": kind, "targets": list(targets), "values": values, "params": params}


# ------------------------------------------------------------------------------------------ validation
@dataclass
class Effect:
    """One validated effect on one target: the kind, the target (joint/link name, root name or None),
    and every parameter by name in absolute units (the headline under its own name too)."""

    kind: str
    target: str | None
    values: dict = field(default_factory=dict)

    @property
    def spec(self) -> EffectKind:
        return KINDS[self.kind]


def _check_value(kind: str, p: Parameter, v, robot, joint: str | None, target) -> float | list:
    where = f"effect {kind!r} on {target!r}: parameter {p.name!r}"
    if p.vector:
        try:
            vec = np.asarray(v, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"{where} must be a 3-vector, got {v!r}") from None
        if vec.shape != (3,) or not np.all(np.isfinite(vec)) or abs(np.linalg.norm(vec) - 1.0) > 1e-6:
            raise ValueError(f"{where} must be a finite unit 3-vector, got {v!r}")
        return vec.tolist()
    if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) or not math.isfinite(v):
        raise ValueError(f"{where} must be a finite number, got {v!r}")
    s = _scaled(p, robot, joint)
    lo, hi = p.valid[0] * s, p.valid[1] * s
    mag = abs(float(v)) if p.signed else float(v)
    if not (lo <= mag <= hi):
        unit = f" ({p.valid[0]:g}-{p.valid[1]:g} x {p.scale} {s:g})" if p.scale else ""
        raise ValueError(f"{where} = {float(v):g} {p.unit} is out of its range [{lo:g}, {hi:g}]{unit}"
                         + (" in magnitude" if p.signed else ""))
    return float(v)


def validate_hidden(hidden, robot, fixed_base: bool) -> list[Effect]:
    """Check hidden effects (module docstring shape) and flatten them to one :class:`Effect` per target.

    Raises:
        ValueError: not a list of dicts; a missing or unknown key; an unknown kind; a kind that acts only
            with a floating base on a fixed base; a target of the wrong sort (an unknown joint or link, a
            HipYawPitch joint, a root kind not on the root, a global kind with a target); lengths of
            ``targets``/``values``/``params`` that differ; a value out of its range; an unknown parameter;
            the same kind twice on one target, or two exclusive kinds on one joint (two backlash forms,
            two friction forms).
    """
    if isinstance(hidden, dict) or not isinstance(hidden, (list, tuple)):
        raise ValueError(f"hidden effects must be a list of dicts, got {type(hidden).__name__}")
    plain = set(plain_joints(robot))
    links = {j.child: j for j in robot.joints}
    out: list[Effect] = []
    seen: dict = {}
    for e in hidden:
        if not isinstance(e, dict):
            raise ValueError(f"a hidden effect must be a dict, got {e!r}")
        unknown = set(e) - {"family", "targets", "values", "params", "peak"}
        missing = {"family", "targets", "values"} - set(e)
        if missing or unknown:
            raise ValueError(f"hidden effect {e!r}: missing keys {sorted(missing)}, unknown keys {sorted(unknown)}")
        kind = e["family"]
        spec = _kind(kind)
        if spec.floating_only and fixed_base:
            raise ValueError(f"effect kind {kind!r} acts only with a floating base (fixed_base=False)")
        targets, values = list(e["targets"]), list(e["values"])
        params = list(e.get("params") or [{}] * len(targets))
        if not targets or len(values) != len(targets) or len(params) != len(targets):
            raise ValueError(f"effect {kind!r}: need one value and one params dict per target, got "
                             f"{len(targets)} targets, {len(values)} values, {len(params)} params")
        for t, v, pr in zip(targets, values, params):
            if spec.target == "joint":
                if t not in plain:
                    why = "it is one of a mimic pair driven by one motor" if t in robot.joint_names else "unknown"
                    raise ValueError(f"effect {kind!r}: target {t!r} is not a joint it can act on ({why}); "
                                     f"joints: {', '.join(sorted(plain))}")
            elif spec.target == "link":
                if t not in links or links[t].name not in plain:
                    raise ValueError(f"effect {kind!r}: target {t!r} is not a link of {robot.name} other than the "
                                     f"root below a single-motor joint")
            elif spec.target == "root":
                if t != robot.root:
                    raise ValueError(f"effect {kind!r} targets the root {robot.root!r}, got {t!r}")
            elif t is not None:
                raise ValueError(f"effect {kind!r} is global: its target must be None, got {t!r}")
            if not isinstance(pr, dict):
                raise ValueError(f"effect {kind!r} on {t!r}: params must be a dict, got {pr!r}")
            names = {p.name for p in spec.extra}
            bad = set(pr) - names
            if bad:
                raise ValueError(f"effect {kind!r}: unknown parameter(s) {sorted(bad)}; known: {sorted(names) or 'none'}")
            joint = t if spec.target == "joint" else None
            vals = {spec.value.name: _check_value(kind, spec.value, v, robot, joint, t)}
            for p in spec.extra:
                if p.name in pr:
                    raw = pr[p.name]
                elif p.vector:
                    raw = [1.0, 0.0, 0.0]
                elif p.default is not None:
                    raw = p.default
                else:
                    raw = float(np.mean(p.draw[0])) * _scaled(p, robot, joint)
                vals[p.name] = _check_value(kind, p, raw, robot, joint, t)
            if kind == "latency_lowpass" and abs(vals["delay"] / PHYSICS_DT - np.rint(vals["delay"] / PHYSICS_DT)) > 1e-6:
                raise ValueError(f"effect 'latency_lowpass': delay {vals['delay']:g} s is not a whole number of "
                                 f"physics steps ({PHYSICS_DT:g} s)")
            for group in ({kind},) + EXCLUSIVE:
                if kind in group:
                    for other in group:
                        if (other, t) in seen:
                            raise ValueError(f"effect {kind!r} on {t!r} clashes with {other!r} on the same target")
            seen[(kind, t)] = True
            out.append(Effect(kind, t, vals))
    return out


# ------------------------------------------------------------------------------------------ compiled
#: The world refuses hidden effects whose :func:`stability_index` exceeds this (draws stay within
#: :data:`STABILITY_BUDGET`; two drawn effects on one joint may add up to more).
STABILITY_LIMIT = 3.3


@dataclass
class Servo:
    """Per-joint constants of the servo loop for a set of effects (arrays (n,), ``robot.joint_names`` order).

    Attributes:
        kp, kd: PD gains [N m/rad], [N m s/rad] after kp_error / kd_error.
        gain: torque-constant factor (servo_gain), applied to the clipped PD torque and its ceiling.
        ceiling: torque ceiling [N m] before ``gain`` (effort x torque_saturation scale).
        no_load_speed: [rad/s] of the torque-speed envelope (inf: none).
        loop_bias: encoder offset the servo sees [rad]; read_bias: offset of the logged angle [rad].
        gear: joint index -> (motor_side, half gap [rad], contact stiffness [N m/rad], contact damping [N m s/rad]).
        friction: joint index -> (tau_c [N m], tau_s [N m], omega_s [rad/s], delta, b [N m s/rad], sigma0 [N m/rad]).
        delay: transport delay [s]; time_constant: command lag [s] (0: none).
        foot_friction: the feet's friction coefficient (None: nominal); ground: (rms height, wavelength) [m] or None.
        index: :func:`stability_index` of the loop (stiffness: gain kp, plus sigma0; motor-side backlash: the
            contact seen through the motor; damping: gain kd plus viscous friction).
    """

    kp: np.ndarray
    kd: np.ndarray
    gain: np.ndarray
    ceiling: np.ndarray
    no_load_speed: np.ndarray
    loop_bias: np.ndarray
    read_bias: np.ndarray
    gear: dict = field(default_factory=dict)
    friction: dict = field(default_factory=dict)
    delay: float = 0.0
    time_constant: float = 0.0
    foot_friction: float | None = None
    ground: tuple | None = None
    index: float = 0.0


def compile_effects(robot, effects: list[Effect], dt: float = PHYSICS_DT, limit: float = STABILITY_LIMIT,
                    presliding: float | None = None) -> Servo:
    """The servo-loop constants (:class:`Servo`) of validated ``effects`` (:func:`validate_hidden`) on
    ``robot`` at the physics step ``dt`` [s].

    Raises:
        ValueError: a :func:`stability_index` above ``limit`` (the explicit loop at ``dt`` would be too close
            to its stability bound: the recordings would show numerical chatter, not physics), or, with
            ``presliding`` [rad] given, a friction whose presliding deflection the stability budget pushes
            above it.
    """
    n = len(robot.joint_names)
    col = {name: i for i, name in enumerate(robot.joint_names)}
    kp_s, kd_s, gain, ceil = np.ones(n), np.ones(n), np.ones(n), np.ones(n)
    w0 = np.full(n, np.inf)
    loop_bias, read_bias = np.zeros(n), np.zeros(n)
    out = Servo(kp_s, kd_s, gain, ceil, w0, loop_bias, read_bias)
    fric = {}
    for e in effects:
        v = e.values
        j = col.get(e.target)
        if e.kind == "servo_gain":
            gain[j] *= v["scale"]
        elif e.kind == "kp_error":
            kp_s[j] *= v["scale"]
        elif e.kind == "kd_error":
            kd_s[j] *= v["scale"]
        elif e.kind == "torque_saturation":
            ceil[j] = v["scale"]
        elif e.kind == "torque_speed":
            w0[j] = v["no_load_speed"]
        elif e.kind == "encoder_offset":
            loop_bias[j] += v["offset"]
            read_bias[j] += v["offset"]
        elif e.kind == "readout_offset":
            read_bias[j] += v["offset"]
        elif e.kind in ("backlash_motor", "backlash_link"):
            kc, bc = contact_parameters(robot, e.target)
            out.gear[j] = (e.kind == "backlash_motor", v["gap"] / 2.0, kc, bc)
        elif e.kind in ("friction_coulomb_viscous", "friction_stribeck"):
            fric[j] = v
        elif e.kind == "latency_lowpass":
            out.delay, out.time_constant = v["delay"], v["time_constant"]
        elif e.kind == "foot_friction":
            out.foot_friction = v["mu"]
        elif e.kind == "uneven_ground":
            out.ground = (v["rms_height"], v["wavelength"])
    out.kp, out.kd = robot.kp * kp_s, robot.kd * kd_s
    out.ceiling = robot.effort * ceil
    K, C = gain * out.kp, gain * out.kd
    for j, (motor_side, _, _, _) in out.gear.items():
        if motor_side:
            K[j], C[j] = contact_stiffness_seen(robot, robot.joint_names[j], K[j], C[j], dt)
    for j, v in fric.items():
        C[j] += v["viscous"]
    for j in sorted(fric):
        v = fric[j]
        tc = v["coulomb"]
        ts = tc * v.get("stiction_ratio", 1.0)
        s0 = bristle_stiffness(robot, robot.joint_names[j], ts, K, C, dt)
        if presliding is not None and ts / s0 > presliding * (1 + 1e-9):
            raise ValueError(f"friction on {robot.joint_names[j]!r}: the 1 kHz stability budget leaves a bristle "
                             f"stiffness of {s0:.3g} N m/rad, a presliding deflection of {ts / s0:.3g} rad > {presliding:g}")
        K[j] += s0
        out.friction[j] = (tc, ts, v.get("stribeck_speed", 1.0), v.get("stribeck_exponent", 1.0), v["viscous"], s0)
    out.index = stability_index(robot, K, C, dt)
    if out.index > limit:
        raise ValueError(f"these hidden effects put the explicit PD loop at {dt:g} s near its stability bound "
                         f"(index {out.index:.2f} > {limit:g}; 4 is unstable): {', '.join(sorted({e.kind for e in effects}))}")
    return out
