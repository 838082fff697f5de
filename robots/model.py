"""The generic robot model both engines, the walk engine and the diagnosis read: joints, links,
limits, gains, frames, poses, written as one URDF.

A robot is data, not code: :class:`RobotModel` holds everything robot-specific that the rest of the
project uses; :func:`robots.nao.nao_h25` builds the NAO-like H25 from its spec, and
:mod:`robots.urdf_robots` builds the humanoids of ``example-robot-data`` from their URDFs. Optional
capabilities are fields that are None for robots without them (``leg_geometry``: the NAO family's
legs, with a closed-form inverse kinematics; ``sole``: a sole rectangle given as data).
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass, field
from xml.sax.saxutils import escape

import numpy as np
from common.files import atomic_write_text


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


@dataclass(frozen=True)
class LegGeometry:
    """The dimensions of a NAO-family leg [m]: hip joint offset from the root (y, z), thigh and tibia
    lengths, ankle height above the sole (the closed-form IK of ``walk_engine.kinematics``)."""

    hip_offset_y: float
    hip_offset_z: float
    thigh: float
    tibia: float
    foot_height: float


@dataclass
class RobotModel:
    """A humanoid as both engines see it: the NAO-like H25 (:func:`robots.nao.nao_h25`) or a humanoid
    of ``example-robot-data`` (:mod:`robots.urdf_robots`).

    Attributes (arrays are ordered like :attr:`joint_names`; the NAO has 24 hinges):
        name: the robot's one name (``robots.get_robot``).
        joint_names: joint names in URDF order.
        lower, upper: joint position limits [rad], shape (n,).
        effort: torque limits [N m], shape (n,).  velocity: speed limits [rad/s], shape (n,).
        kp [N m/rad], kd [N m s/rad]: PD gains, shape (n,).
        groups: ``{"legs", "arms", "head", "left_leg", "right_leg"}`` -> joint names.
        frames: named rigid frames (``l_sole``, ``r_sole``, ``gyro``, ``accel``, FSRs).
        mimic: ``{follower: leader}``: joints that one motor drives together (the NAO's
            ``RHipYawPitch`` follows ``LHipYawPitch``).

    Raises:
        ValueError: a group that names an unknown joint.
    """

    name: str
    joints: tuple[JointSpec, ...]
    root: str
    root_inertial: Inertial
    root_geoms: tuple[Geom, ...]
    #: ``{"legs", "left_leg", "right_leg", "arms", "head"}`` -> joint names
    group_names: dict[str, tuple[str, ...]]
    #: root origin lower than this above the terrain [m] is a fall (``envs.base``)
    fall_height: float
    frames: dict[str, Frame] = field(default_factory=dict)
    poses: dict[str, dict[str, float]] = field(default_factory=dict)
    #: height [m] of the root origin when the base is fixed (actuator tests, excitation logs)
    hang_height: float = 0.6
    #: where the description comes from (a URDF path, or a spec)
    source: str = ""
    #: the legs' dimensions where the robot's legs have the NAO's topology (two legs of six hinges
    #: sharing one hip yaw-pitch motor), for the walk engine's closed-form IK; None: each leg by its
    #: own numerical IK (``walk_engine.legs.LegChain``)
    leg_geometry: LegGeometry | None = None
    #: the sole rectangle in the sole frame, ``(front, back, inner, outer)`` [m] (the walk engine's
    #: support polygon); None: taken from the left foot's collision box
    sole: tuple[float, float, float, float] | None = None

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
        self.groups = {k: tuple(v) for k, v in self.group_names.items()}
        unknown = sorted({n for v in self.groups.values() for n in v} - set(idx))
        if unknown:
            raise ValueError(f"{self.name}: groups name unknown joints {', '.join(unknown)}")

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


__all__ = ["Frame", "Geom", "Inertial", "JointSpec", "LegGeometry", "RobotModel"]
