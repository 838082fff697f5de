"""A NAO-like H25 humanoid built from primitives: one Python spec -> one URDF for both engines.

Kinematics, joint limits, effort/velocity limits and CoM-based inertials are those of the
ros-naoqi V50 URDF (github.com/ros-naoqi/nao_robot,
``nao_description/urdf/naoV50_generated_urdf/nao.urdf``, BSD; its link lengths match Aldebaran's
"H25 - Links" documentation). Collision geometry is primitive (boxes, capsules, spheres); only
the foot sole is sourced: a 160 x 88.8 mm box whose bottom face lies 45.11 mm below the ankle-roll
axis, centred 30 mm forward and 5.62 mm outward of the ankle (the sole outline of
RoboCup SPL team code's B-Human-style robot dimensions, consistent with the FSR and foot-bumper
frames of the V50 URDF).

Design choices (see README "Robot model"):

* No massless frame links. The URDF root is ``torso`` (MuJoCo's URDF import would weld a
  ``base_link`` root to the world; PyBullet gives inertia-less links 1 kg). Sole, IMU and FSR
  frames are exposed as (parent link, offset) :class:`Frame` objects instead.
* 24 hinges: head 2, arms 2x5, legs 2x6; the hands are dropped and their mass stays in
  ``l_wrist``/``r_wrist`` (the V50 URDF's wrist link already carries it).
* ``RHipYawPitch`` mimics ``LHipYawPitch`` (one motor; ``<mimic>`` in the V50 URDF). The action
  space therefore has 23 actuated joints; the right HipYawPitch target always equals the left one.
"""

from __future__ import annotations

import functools
import math
import os
import tempfile
from dataclasses import dataclass, field
from xml.sax.saxutils import escape

import numpy as np
from common.files import atomic_write_text

# --------------------------------------------------------------------------------------------
# Named lengths [m] (V50 URDF joint origins; Aldebaran "H25 - Links")
NECK_OFFSET_Z = 0.1265
SHOULDER_OFFSET_Y = 0.098
SHOULDER_OFFSET_Z = 0.100
UPPER_ARM_LENGTH = 0.105
ELBOW_OFFSET_Y = 0.015
LOWER_ARM_LENGTH = 0.05595
HIP_OFFSET_Y = 0.050
HIP_OFFSET_Z = 0.085
THIGH_LENGTH = 0.100
TIBIA_LENGTH = 0.1029
FOOT_HEIGHT = 0.04511

# Foot sole (source: module docstring), in the ankle-roll frame of the left foot.
SOLE_LENGTH = 0.160
SOLE_WIDTH = 0.0888
SOLE_CENTER_X = 0.030
SOLE_CENTER_Y_OUT = 0.00562
SOLE_THICKNESS = 0.015  # primitive choice: a 15 mm plate

# IMU in the torso frame (the V50 URDF's ``ImuTorso*`` frames).
GYRO_OFFSET = (-0.008, 0.006, 0.029)
ACCEL_OFFSET = (-0.008, 0.00606, 0.027)
# FSRs in the left ankle-roll frame, at the sole plane (the V50 URDF's ``*Fsr*_frame`` frames);
# right foot mirrors y.
FSR_XY_LEFT = {"FL": (0.07025, 0.0299), "FR": (0.07025, -0.0231), "RL": (-0.03025, 0.0299),
               "RR": (-0.02965, -0.0191)}

_S = 1.0 / math.sqrt(2.0)


@dataclass(frozen=True)
class Inertial:
    """Link mass [kg], CoM in the link frame [m], inertia about the CoM [kg m^2]."""

    mass: float
    com: tuple[float, float, float]
    inertia: tuple[float, float, float, float, float, float]  # ixx, iyy, izz, ixy, ixz, iyz

    def mirrored(self) -> "Inertial":
        """Mirror in y (left -> right): CoM y and the products ixy, iyz change sign."""
        x, y, z = self.com
        ixx, iyy, izz, ixy, ixz, iyz = self.inertia
        return Inertial(self.mass, (x, -y, z), (ixx, iyy, izz, -ixy, ixz, -iyz))


@dataclass(frozen=True)
class Geom:
    """A primitive collision geometry in the link frame.

    kind: "box" (size = full extents x, y, z), "capsule" (size = radius, length of the
    cylindrical part; axis along the local z of the geom), "sphere" (size = radius), "mesh"
    (size = scale x, y, z; ``mesh`` = absolute path of the mesh file).
    rpy: roll, pitch, yaw of the geom frame [rad].
    collide: False for a visual-only geom (written as URDF ``<visual>`` alone).
    """

    kind: str
    size: tuple[float, ...]
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    collide: bool = True
    mesh: str | None = None

    def mirrored(self) -> "Geom":
        x, y, z = self.xyz
        r, p, yw = self.rpy
        return Geom(self.kind, self.size, (x, -y, z), (-r, p, -yw), self.collide, self.mesh)


@dataclass(frozen=True)
class JointSpec:
    """A hinge joint and the child link it moves.

    limits [rad], effort [N m], velocity [rad/s] from the V50 URDF; kp [N m/rad], kd [N m s/rad]
    are this project's PD gains (the same in both engines).
    """

    name: str
    parent: str
    child: str
    xyz: tuple[float, float, float]
    axis: tuple[float, float, float]
    lower: float
    upper: float
    effort: float
    velocity: float
    kp: float
    kd: float
    inertial: Inertial
    geoms: tuple[Geom, ...] = ()
    mimic: str | None = None
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)  # joint origin rotation (URDF ``<origin rpy>``)


@dataclass(frozen=True)
class Frame:
    """A frame rigidly attached to a link: position ``offset`` [m] in the link frame."""

    link: str
    offset: tuple[float, float, float]


# --------------------------------------------------------------------------------------------
# Inertials from the V50 URDF (about the CoM, as URDF expects), left side.
TORSO = Inertial(1.04956, (-0.00413, 0.0, 0.04342),
                 (3.08361e-3, 2.88350e-3, 1.59240e-3, 1.43e-5, -3.30e-5, -2.71e-5))
NECK = Inertial(0.07842, (-0.00001, 0.0, -0.02742), (1.603e-5, 1.704e-5, 5.53e-6, 0, 0, 0))
HEAD = Inertial(0.60533, (-0.00112, 0.0, 0.05258), (9.578e-4, 8.168e-4, 9.850e-4, 8.8e-6, 5.3e-6, -3.0e-5))
PELVIS = Inertial(0.06981, (-0.00781, -0.01114, 0.02661), (2.341e-5, 4.764e-5, 4.970e-5, 1.1e-6, -1.8e-6, 2.8e-6))
HIP = Inertial(0.14053, (-0.01549, 0.00029, -0.00515), (2.384e-5, 6.082e-5, 5.437e-5, -6.5e-7, 7.1e-6, -2.1e-7))
THIGH = Inertial(0.38968, (0.00138, 0.00221, -0.05373), (5.098e-4, 4.654e-4, 3.011e-4, 2.1e-6, 5.64e-5, -7.9e-6))
TIBIA = Inertial(0.30142, (0.00453, 0.00225, -0.04936), (4.462e-4, 3.881e-4, 1.855e-4, 3.7e-6, -3.09e-5, 6.0e-6))
ANKLE_PITCH = Inertial(0.13416, (0.00045, 0.00029, 0.00685), (3.220e-5, 6.794e-5, 5.483e-5, 0.0, 4.3e-6, 2.8e-7))
FOOT = Inertial(0.17184, (0.02542, 0.0033, -0.03239), (8.729e-5, 3.530e-4, 4.128e-4, 8.7e-6, -2.1e-6, 3.7e-7))
SHOULDER = Inertial(0.09304, (-0.00165, -0.02663, 0.00014), (1.830e-5, 1.390e-5, 2.019e-5, 2.1e-6, 0.0, -3.7e-7))
BICEP = Inertial(0.15777, (0.02455, 0.00563, 0.0033), (8.718e-5, 2.747e-4, 2.418e-4, -2.5e-5, -1.4e-5, 4.7e-7))
ELBOW = Inertial(0.06483, (-0.02744, 0.0, -0.00014), (5.60e-6, 2.662e-5, 2.763e-5, 0, 0, 0))
FOREARM = Inertial(0.07761, (0.02556, 0.00281, 0.00076), (2.467e-5, 3.838e-5, 3.597e-5, 3.2e-6, 1.6e-6, 1.4e-7))
WRIST = Inertial(0.18533, (0.03434, -0.00088, 0.00308), (6.865e-5, 1.358e-4, 1.332e-4, 1.2e-7, -2.9e-6, 2.7e-6))

# PD gains [N m/rad], [N m s/rad] per joint family. Explicit PD on armature-free links (PyBullet
# has no joint armature: its ``changeDynamics``, PyBullet Quickstart Guide, offers none) is stable
# only while kd*dt/I and kp*dt^2/I stay small, where I is
# the smallest effective joint inertia 1/(M^-1)_ii (hanging robot, crouch pose): 4e-5 kg m^2 for
# WristYaw, 1.8e-4 for AnkleRoll. At the 1 ms physics step these gains keep kd*dt/I <= 0.5 and
# kp*dt^2/I <= 0.2, with damping ratio ~0.8 against the joint's own mass-matrix diagonal where that
# bound allows; a 0.1 rad error saturates the leg motors (effort 3.0-3.3 N m).
GAINS = {
    "Head": (5.0, 0.10),
    "HipYawPitch": (30.0, 0.40), "HipRoll": (30.0, 1.00), "HipPitch": (30.0, 0.60),
    "KneePitch": (30.0, 0.60), "AnklePitch": (30.0, 0.23), "AnkleRoll": (30.0, 0.09),
    "ShoulderPitch": (8.0, 0.40), "ShoulderRoll": (8.0, 0.30), "ElbowYaw": (3.0, 0.04),
    "ElbowRoll": (3.0, 0.11), "WristYaw": (1.0, 0.013),
}


def _leg(side: str) -> list[JointSpec]:
    s = 1.0 if side == "L" else -1.0
    low = side.lower()
    m = (lambda i: i) if side == "L" else (lambda i: i.mirrored())
    mg = (lambda g: g) if side == "L" else (lambda g: g.mirrored())
    foot_geom = Geom("box", (SOLE_LENGTH, SOLE_WIDTH, SOLE_THICKNESS),
                     (SOLE_CENTER_X, SOLE_CENTER_Y_OUT, -FOOT_HEIGHT + SOLE_THICKNESS / 2))
    thigh_geom = Geom("capsule", (0.033, 0.060), (0.0, 0.0, -0.050))
    tibia_geom = Geom("capsule", (0.030, 0.060), (0.0, 0.0, -0.052))

    def lim(lo, hi):  # right side mirrors roll limits
        return (lo, hi) if side == "L" else (-hi, -lo)

    j = []
    j.append(JointSpec(f"{side}HipYawPitch", "torso", f"{side}Pelvis", (0.0, s * HIP_OFFSET_Y, -HIP_OFFSET_Z),
                       (0.0, _S, -_S) if side == "L" else (0.0, _S, _S), -1.1453, 0.7407, 3.348, 4.162,
                       *GAINS["HipYawPitch"], m(PELVIS), (), None if side == "L" else "LHipYawPitch"))
    j.append(JointSpec(f"{side}HipRoll", f"{side}Pelvis", f"{side}Hip", (0, 0, 0), (1, 0, 0),
                       *lim(-0.3794, 0.7905), 3.348, 4.162, *GAINS["HipRoll"], m(HIP)))
    j.append(JointSpec(f"{side}HipPitch", f"{side}Hip", f"{side}Thigh", (0, 0, 0), (0, 1, 0),
                       -1.5359, 0.4840, 3.023, 6.402, *GAINS["HipPitch"], m(THIGH), (mg(thigh_geom),)))
    j.append(JointSpec(f"{side}KneePitch", f"{side}Thigh", f"{side}Tibia", (0, 0, -THIGH_LENGTH), (0, 1, 0),
                       -0.0923, 2.1126, 3.023, 6.402, *GAINS["KneePitch"], m(TIBIA), (mg(tibia_geom),)))
    ap_lo, ap_hi = (-1.1894, 0.9226) if side == "L" else (-1.1863, 0.9320)
    j.append(JointSpec(f"{side}AnklePitch", f"{side}Tibia", f"{side}AnklePitch", (0, 0, -TIBIA_LENGTH),
                       (0, 1, 0), ap_lo, ap_hi, 3.023, 6.402, *GAINS["AnklePitch"], m(ANKLE_PITCH)))
    j.append(JointSpec(f"{side}AnkleRoll", f"{side}AnklePitch", f"{low}_ankle", (0, 0, 0), (1, 0, 0),
                       *lim(-0.3978, 0.7690), 3.348, 4.162, *GAINS["AnkleRoll"], m(FOOT), (mg(foot_geom),)))
    return j


def _arm(side: str) -> list[JointSpec]:
    s = 1.0 if side == "L" else -1.0
    low = side.lower()
    m = (lambda i: i) if side == "L" else (lambda i: i.mirrored())
    mg = (lambda g: g) if side == "L" else (lambda g: g.mirrored())

    def lim(lo, hi):
        return (lo, hi) if side == "L" else (-hi, -lo)

    upper = Geom("capsule", (0.025, 0.070), (0.060, 0.0, 0.0), (0.0, math.pi / 2, 0.0))
    fore = Geom("capsule", (0.022, 0.080), (0.060, 0.0, 0.0), (0.0, math.pi / 2, 0.0))
    return [
        JointSpec(f"{side}ShoulderPitch", "torso", f"{side}Shoulder", (0.0, s * SHOULDER_OFFSET_Y, SHOULDER_OFFSET_Z),
                  (0, 1, 0), -2.0857, 2.0857, 1.329, 8.268, *GAINS["ShoulderPitch"], m(SHOULDER)),
        JointSpec(f"{side}ShoulderRoll", f"{side}Shoulder", f"{side}Bicep", (0, 0, 0), (0, 0, 1),
                  *lim(-0.3142, 1.3265), 1.7835, 7.194, *GAINS["ShoulderRoll"], m(BICEP), (mg(upper),)),
        JointSpec(f"{side}ElbowYaw", f"{side}Bicep", f"{side}Elbow", (UPPER_ARM_LENGTH, s * ELBOW_OFFSET_Y, 0.0),
                  (1, 0, 0), -2.0857, 2.0857, 1.547, 8.268, *GAINS["ElbowYaw"], m(ELBOW)),
        JointSpec(f"{side}ElbowRoll", f"{side}Elbow", f"{side}ForeArm", (0, 0, 0), (0, 0, 1),
                  *lim(-1.5446, -0.0349), 1.532, 7.194, *GAINS["ElbowRoll"], m(FOREARM)),
        JointSpec(f"{side}WristYaw", f"{side}ForeArm", f"{low}_wrist", (LOWER_ARM_LENGTH, 0.0, 0.0),
                  (1, 0, 0), -1.8238, 1.8238, 0.4075, 24.62, *GAINS["WristYaw"], m(WRIST), (mg(fore),)),
    ]


def _head() -> list[JointSpec]:
    return [
        JointSpec("HeadYaw", "torso", "Neck", (0.0, 0.0, NECK_OFFSET_Z), (0, 0, 1), -2.0857, 2.0857, 1.547, 8.268,
                  *GAINS["Head"], NECK),
        JointSpec("HeadPitch", "Neck", "Head", (0, 0, 0), (0, 1, 0), -0.6720, 0.5149, 1.532, 7.194,
                  *GAINS["Head"], HEAD, (Geom("sphere", (0.060,), (0.0, 0.0, 0.058)),)),
    ]


TORSO_GEOMS = (Geom("box", (0.080, 0.140, 0.180), (-0.010, 0.0, 0.030)),)

# Standing poses [rad] by joint name; joints not named are 0.
ARMS_DOWN = {"LShoulderPitch": 1.45, "RShoulderPitch": 1.45, "LShoulderRoll": 0.15, "RShoulderRoll": -0.15,
             "LElbowYaw": -1.2, "RElbowYaw": 1.2, "LElbowRoll": -0.45, "RElbowRoll": 0.45}


def _leg_pose(hip: float, knee: float, ankle: float) -> dict[str, float]:
    out = {}
    for side in "LR":
        out.update({f"{side}HipPitch": hip, f"{side}KneePitch": knee, f"{side}AnklePitch": ankle})
    return out


POSES = {
    "zero": {},
    "stand": {**ARMS_DOWN},
    "crouch": {**ARMS_DOWN, **_leg_pose(-0.45, 0.9, -0.45)},
    "deep_crouch": {**ARMS_DOWN, **_leg_pose(-0.6, 1.2, -0.6)},
}


@dataclass
class RobotModel:
    """A humanoid as both engines see it: the NAO-like H25 (:func:`nao_h25`) or a humanoid of
    ``example-robot-data`` (:mod:`robots.urdf_robots`).

    Attributes (arrays are ordered like :attr:`joint_names`; the NAO has 24 hinges):
        joint_names: NAO joint names in URDF order.
        lower, upper: joint position limits [rad], shape (n,).
        effort: torque limits [N m], shape (n,).  velocity: speed limits [rad/s], shape (n,).
        kp [N m/rad], kd [N m s/rad]: PD gains, shape (n,).
        groups: ``{"legs", "arms", "head", "left_leg", "right_leg"}`` -> joint names.
        frames: named rigid frames (``l_sole``, ``r_sole``, ``gyro``, ``accel``, FSRs).
        mimic: ``{follower: leader}`` (``RHipYawPitch`` follows ``LHipYawPitch``).

    Source: ros-naoqi V50 URDF (github.com/ros-naoqi/nao_robot, ``nao_description``).
    """

    name: str
    joints: tuple[JointSpec, ...]
    root: str = "torso"
    root_inertial: Inertial = TORSO
    root_geoms: tuple[Geom, ...] = TORSO_GEOMS
    frames: dict[str, Frame] = field(default_factory=dict)
    poses: dict[str, dict[str, float]] = field(default_factory=dict)
    #: torso (root) origin lower than this above the terrain [m] is a fall (``envs.base``)
    fall_height: float = 0.20
    #: height [m] of the root origin when the base is fixed (actuator tests, excitation logs)
    hang_height: float = 0.6
    #: ``{"legs", "left_leg", "right_leg", "arms", "head"}`` -> joint names; None: NAO naming
    group_names: dict[str, tuple[str, ...]] | None = None
    #: where the description comes from (URDF path, or the NAO spec)
    source: str = "robots.nao (ros-naoqi V50 URDF)"

    def __post_init__(self) -> None:
        self.joint_names = tuple(j.name for j in self.joints)
        self.lower = np.array([j.lower for j in self.joints])
        self.upper = np.array([j.upper for j in self.joints])
        self.effort = np.array([j.effort for j in self.joints])
        self.velocity = np.array([j.velocity for j in self.joints])
        self.kp = np.array([j.kp for j in self.joints])
        self.kd = np.array([j.kd for j in self.joints])
        self.mimic = {j.name: j.mimic for j in self.joints if j.mimic}
        self.actuated_joint_names = tuple(n for n in self.joint_names if n not in self.mimic)
        idx = {n: i for i, n in enumerate(self.joint_names)}
        # Expand a 23-vector of actuated targets to all 24 joints (mimic joints copy their leader).
        self.actuated_to_joint = np.array(
            [self.actuated_joint_names.index(self.mimic.get(n, n)) for n in self.joint_names])
        self.actuated_index = np.array([idx[n] for n in self.actuated_joint_names])
        if self.group_names is not None:
            self.groups = {k: tuple(v) for k, v in self.group_names.items()}
            return
        legs = [n for n in self.joint_names if any(k in n for k in ("Hip", "Knee", "Ankle"))]
        self.groups = {
            "legs": tuple(legs),
            "left_leg": tuple(n for n in legs if n.startswith("L")),
            "right_leg": tuple(n for n in legs if n.startswith("R")),
            "arms": tuple(n for n in self.joint_names if any(k in n for k in ("Shoulder", "Elbow", "Wrist"))),
            "head": tuple(n for n in self.joint_names if n.startswith("Head")),
        }

    # ------------------------------------------------------------------ convenience
    @property
    def links(self) -> tuple[str, ...]:
        return (self.root,) + tuple(j.child for j in self.joints)

    @property
    def total_mass(self) -> float:
        """Sum of link masses [kg]."""
        return self.root_inertial.mass + sum(j.inertial.mass for j in self.joints)

    def joint_index(self, names) -> np.ndarray:
        """Indices of ``names`` in :attr:`joint_names`; raises KeyError naming an unknown joint."""
        idx = {n: i for i, n in enumerate(self.joint_names)}
        try:
            return np.array([idx[n] for n in names], dtype=int)
        except KeyError as exc:
            raise KeyError(f"unknown joint {exc.args[0]!r}; known: {', '.join(self.joint_names)}") from None

    def pose(self, name: str = "crouch", actuated: bool = False) -> np.ndarray:
        """Joint angles [rad] of a named pose, shape (24,) or (23,) if ``actuated``."""
        if name not in self.poses:
            raise KeyError(f"unknown pose {name!r}; known: {', '.join(self.poses)}")
        q = np.array([self.poses[name].get(n, 0.0) for n in self.joint_names])
        return q[self.actuated_index] if actuated else q

    def expand_action(self, a: np.ndarray) -> np.ndarray:
        """Map actuated targets, shape (..., 23), to all joints, shape (..., 24)."""
        return np.asarray(a)[..., self.actuated_to_joint]

    # ------------------------------------------------------------------ URDF
    def urdf(self) -> str:
        """URDF text of the model (primitive collision geometry, CoM-based inertials)."""
        return _urdf_text(self)

    def write_urdf(self, path: str | os.PathLike | None = None) -> str:
        """Write the URDF atomically to ``path`` (default: a per-process cache file); return the path."""
        text = self.urdf()
        if path is None:
            path = os.path.join(tempfile.gettempdir(), f"sgatwalk_{self.name}_{os.getuid()}_{hash(text) & 0xFFFFFFF:x}.urdf")
            if os.path.exists(path):
                return path
        path = os.fspath(path)
        atomic_write_text(path, text)
        return path


def _fmt(v) -> str:
    return " ".join(f"{x:.9g}" for x in v)


def _inertial_xml(i: Inertial) -> str:
    ixx, iyy, izz, ixy, ixz, iyz = i.inertia
    return (f'    <inertial><origin xyz="{_fmt(i.com)}" rpy="0 0 0"/><mass value="{i.mass:.9g}"/>'
            f'<inertia ixx="{ixx:.9g}" iyy="{iyy:.9g}" izz="{izz:.9g}" ixy="{ixy:.9g}" ixz="{ixz:.9g}" '
            f'iyz="{iyz:.9g}"/></inertial>\n')


def _geom_xml(g: Geom) -> str:
    if g.kind == "box":
        shape = f'<box size="{_fmt(g.size)}"/>'
    elif g.kind == "sphere":
        shape = f'<sphere radius="{g.size[0]:.9g}"/>'
    elif g.kind == "capsule":
        shape = f'<capsule radius="{g.size[0]:.9g}" length="{g.size[1]:.9g}"/>'
    elif g.kind == "mesh":
        shape = f'<mesh filename="{escape(g.mesh)}" scale="{_fmt(g.size)}"/>'
    else:  # pragma: no cover - spec error
        raise ValueError(f"unknown geom kind {g.kind!r}")
    body = f'<origin xyz="{_fmt(g.xyz)}" rpy="{_fmt(g.rpy)}"/><geometry>{shape}</geometry>'
    visual = f"    <visual>{body}</visual>\n"
    return (f"    <collision>{body}</collision>\n" + visual) if g.collide else visual


def _urdf_text(robot: RobotModel) -> str:
    out = [f'<?xml version="1.0"?>\n<robot name="{escape(robot.name)}">\n']
    out.append(f'  <link name="{robot.root}">\n{_inertial_xml(robot.root_inertial)}')
    out.extend(_geom_xml(g) for g in robot.root_geoms)
    out.append("  </link>\n")
    for j in robot.joints:
        out.append(f'  <link name="{j.child}">\n{_inertial_xml(j.inertial)}')
        out.extend(_geom_xml(g) for g in j.geoms)
        out.append("  </link>\n")
        out.append(
            f'  <joint name="{j.name}" type="revolute"><parent link="{j.parent}"/><child link="{j.child}"/>'
            f'<origin xyz="{_fmt(j.xyz)}" rpy="{_fmt(j.rpy)}"/><axis xyz="{_fmt(j.axis)}"/>'
            f'<limit lower="{j.lower:.9g}" upper="{j.upper:.9g}" effort="{j.effort:.9g}" velocity="{j.velocity:.9g}"/>'
            + (f'<mimic joint="{j.mimic}" multiplier="1" offset="0"/>' if j.mimic else "")
            + "</joint>\n")
    out.append("</robot>\n")
    return "".join(out)


@functools.lru_cache(maxsize=1)
def nao_h25() -> RobotModel:
    """The NAO-like H25 model (24 hinges, 5.3054 kg). Cached: treat it as read-only."""
    joints = tuple(_head() + _arm("L") + _arm("R") + _leg("L") + _leg("R"))
    frames = {
        "l_sole": Frame("l_ankle", (0.0, 0.0, -FOOT_HEIGHT)),
        "r_sole": Frame("r_ankle", (0.0, 0.0, -FOOT_HEIGHT)),
        "gyro": Frame("torso", GYRO_OFFSET),
        "accel": Frame("torso", ACCEL_OFFSET),
    }
    swap = {"FL": "FR", "FR": "FL", "RL": "RR", "RR": "RL"}  # mirroring swaps left and right sensors
    for k, (x, y) in FSR_XY_LEFT.items():
        frames[f"LFsr{k}"] = Frame("l_ankle", (x, y, -FOOT_HEIGHT))
        frames[f"RFsr{swap[k]}"] = Frame("r_ankle", (x, -y, -FOOT_HEIGHT))
    return RobotModel("nao_h25", joints, frames=frames, poses=POSES)
