"""Humanoids of ``example-robot-data`` (Unitree G1, PAL Talos) as :class:`robots.RobotModel`.

The URDFs are read from the installed ``example-robot-data`` package (PyPI wheel of
github.com/Gepetto/example-robot-data, BSD-3-Clause; files under its share path
``cmeel.prefix/share/example-robot-data/robots``); nothing of it is copied into this repository.
Each URDF becomes the same kind of model the NAO is: a tree of hinges whose URDF text both worlds
load (MuJoCo ``MjSpec.from_file``, PyBullet ``loadURDF``), so the two engines see one robot:

* **Fixed joints are merged into their parent** (masses, centres of mass and inertias combined by
  the parallel-axis theorem; visuals and frames re-expressed in the parent). Links without an
  ``<inertial>`` therefore add nothing in either engine: PyBullet would give each of them 1 kg
  (the G1's ``imu_in_torso``, ``imu_in_pelvis``, ``d435_link``, ``mid360_link``: 4 kg that
  MuJoCo does not add), MuJoCo's URDF import would fuse or drop them.
* **Mesh paths** (``package://example-robot-data/robots/...``) are resolved to absolute paths;
  meshes are visual only (Rerun shows them; MuJoCo's URDF import discards visuals).
* **Contact geometry is the documented sole only**: a box per foot, from the URDF's own foot
  collision primitives (G1: the box around its four 5 mm contact spheres; Talos: its
  ``leg_*_6_link`` collision box). The sole frame is the ankle's projection on the box's bottom
  face (the NAO's convention: the walk engine's ZMP offsets and footsteps refer to it).
  Mesh collisions elsewhere are dropped in both engines (the NAO has no self-collision either).
* **PD gains per joint family** from the effort limit and the explicit-PD stability bound at the
  physics step: kp = min(effort / 0.1 rad, 2 I/dt²), kd = min(2·0.8·sqrt(kp·I), I/dt), where I
  is the joint's effective inertia 1/(M⁻¹)ᵢᵢ in the crouch pose (MuJoCo ``mj_fullM``), the smaller
  of the hanging robot's and the free-floating robot's (in flight the torso turns against the leg,
  which lowers a hip's effective inertia below the hanging value), and the smallest of the family.
  Semi-implicit Euler keeps an undamped joint stable for ω·dt < 2 (kp·dt²/I < 4) and an explicit
  damper for kd·dt/I < 2; these bounds keep half of that. The NAO's hand-set gains keep a tenth
  (kp·dt²/I ≤ 0.2): with that margin the G1's light foot limits its ankle roll to 63 N m/rad, which
  sags 0.25 rad under the body in single support. The NAO's hand-set gains follow the same rule
  (``robots.nao.GAINS``: a 0.1 rad error saturates the leg motors).
* The IMU (``gyro``, ``accel`` frames) sits on the root link, whose frame is the base the worlds
  report (G1: ``imu_in_pelvis``; Talos: the root origin, its IMU being on the torso above two
  waist joints).

Robots: ``g1`` (``g1_description/urdf/g1_29dof_rev_1_0.urdf``, 29 hinges) and ``talos``
(``talos_data/robots/talos_reduced_box.urdf``, 32 hinges, grippers as one hinge each).
"""

from __future__ import annotations

import functools
import importlib.metadata
import math
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from common.defaults import PHYSICS_DT
from robots.nao import Frame, Geom, Inertial, JointSpec, RobotModel

#: Max PD error [rad] that saturates a motor (the NAO's rule, ``robots.nao.GAINS``).
SATURATING_ERROR = 0.1
#: Explicit-PD bounds at the physics step: kp·dt²/I and kd·dt/I (half the semi-implicit Euler
#: stability limits 4 and 2, module docstring), and the damping ratio aimed at.
KP_BOUND, KD_BOUND, DAMPING_RATIO = 2.0, 1.0, 0.8
#: Fall threshold as a fraction of the root's height above the soles in the crouch pose (the NAO's
#: 0.20 m is 0.64 of its 0.31 m).
FALL_HEIGHT_FRACTION = 0.6


def robots_dir() -> str:
    """The installed ``example-robot-data``'s ``robots`` folder (absolute path).

    Raises:
        ModuleNotFoundError: the package is not installed (``pip install example-robot-data``).
    """
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        raise ModuleNotFoundError("example-robot-data is not installed: pip install example-robot-data") from None
    path = os.fspath(dist.locate_file("cmeel.prefix/share/example-robot-data/robots"))
    if not os.path.isdir(path):
        raise ModuleNotFoundError(f"example-robot-data is installed but has no robots folder at {path}")
    return path


# ------------------------------------------------------------------------------------- transforms
def _rot(rpy) -> np.ndarray:
    """URDF ``rpy`` (fixed-axis x, y, z) -> rotation matrix (scipy ``from_euler('xyz')``)."""
    return Rotation.from_euler("xyz", rpy).as_matrix()


def _rpy(R: np.ndarray) -> tuple[float, float, float]:
    return tuple(float(v) for v in Rotation.from_matrix(R).as_euler("xyz"))


def _floats(text: str | None, default=(0.0, 0.0, 0.0)) -> tuple[float, ...]:
    return tuple(float(v) for v in text.split()) if text else tuple(default)


@dataclass
class _Body:
    """A URDF link while it is being merged: mass [kg], CoM [m] and inertia about the CoM (3, 3)
    [kg m²] in the link frame, visual/collision geoms, and named frames (position, rotation)."""

    mass: float
    com: np.ndarray
    inertia: np.ndarray
    visuals: list
    collisions: list
    frames: dict

    def absorb(self, other: "_Body", p: np.ndarray, R: np.ndarray) -> None:
        """Merge ``other`` (a child on a fixed joint at position p, rotation R) into this body."""
        oc = p + R @ other.com
        m = self.mass + other.mass
        com = (self.mass * self.com + other.mass * oc) / m if m > 0 else self.com
        inertia = np.zeros((3, 3))
        for mass, c, inertia_c in ((self.mass, self.com, self.inertia), (other.mass, oc, R @ other.inertia @ R.T)):
            d = c - com
            inertia += inertia_c + mass * (d @ d * np.eye(3) - np.outer(d, d))
        self.mass, self.com, self.inertia = m, com, inertia
        for src, dst in ((other.visuals, self.visuals), (other.collisions, self.collisions)):
            dst.extend((p + R @ gp, R @ gR, g) for gp, gR, g in src)
        for name, (fp, fR) in other.frames.items():
            self.frames[name] = (p + R @ fp, R @ fR)


def _parse_geom(el, mesh_root: str):
    """(position (3,), rotation (3, 3), Geom without pose) of a ``<visual>``/``<collision>``; None for
    shapes this project does not load."""
    org = el.find("origin")
    p = np.array(_floats(org.get("xyz") if org is not None else None))
    R = _rot(_floats(org.get("rpy") if org is not None else None))
    g = el.find("geometry")
    if g is None or len(g) == 0:
        return None
    shape = g[0]
    if shape.tag == "box":
        geom = Geom("box", _floats(shape.get("size")))
    elif shape.tag == "sphere":
        geom = Geom("sphere", (float(shape.get("radius")),))
    elif shape.tag == "mesh":
        fn = shape.get("filename")
        prefix = "package://example-robot-data/robots/"
        path = os.path.join(mesh_root, fn[len(prefix):]) if fn.startswith(prefix) else fn
        geom = Geom("mesh", _floats(shape.get("scale"), (1.0, 1.0, 1.0)), collide=False, mesh=os.path.abspath(path))
    else:  # cylinders etc.: not used by the feet; visuals only in these robots
        return None
    return p, R, geom


def _parse(urdf_path: str, mesh_root: str):
    root = ET.parse(urdf_path).getroot()
    bodies: dict[str, _Body] = {}
    for ln in root.findall("link"):
        ine = ln.find("inertial")
        if ine is None:
            mass, com, inertia = 0.0, np.zeros(3), np.zeros((3, 3))
        else:
            org = ine.find("origin")
            com = np.array(_floats(org.get("xyz") if org is not None else None))
            Ri = _rot(_floats(org.get("rpy") if org is not None else None))
            a = ine.find("inertia").attrib
            Ic = np.array([[float(a["ixx"]), float(a["ixy"]), float(a["ixz"])],
                           [float(a["ixy"]), float(a["iyy"]), float(a["iyz"])],
                           [float(a["ixz"]), float(a["iyz"]), float(a["izz"])]])
            mass, inertia = float(ine.find("mass").get("value")), Ri @ Ic @ Ri.T
        vis = [v for v in (_parse_geom(e, mesh_root) for e in ln.findall("visual")) if v is not None]
        col = [v for v in (_parse_geom(e, mesh_root) for e in ln.findall("collision")) if v is not None]
        bodies[ln.get("name")] = _Body(mass, com, inertia, vis, col, {ln.get("name"): (np.zeros(3), np.eye(3))})
    joints = []
    for j in root.findall("joint"):
        org = j.find("origin")
        lim = j.find("limit")
        joints.append({
            "name": j.get("name"), "type": j.get("type"), "parent": j.find("parent").get("link"),
            "child": j.find("child").get("link"),
            "p": np.array(_floats(org.get("xyz") if org is not None else None)),
            "R": _rot(_floats(org.get("rpy") if org is not None else None)),
            "axis": _floats(j.find("axis").get("xyz") if j.find("axis") is not None else None, (1.0, 0.0, 0.0)),
            "limit": None if lim is None else tuple(float(lim.get(k, 0.0)) for k in ("lower", "upper", "effort",
                                                                                    "velocity")),
        })
    return bodies, joints


def _merge_fixed(bodies: dict[str, _Body], joints: list[dict]) -> tuple[str, list[dict]]:
    """Merge every fixed joint's child into its parent (leaves first); return the root link's name
    and the remaining hinges in URDF order, re-expressed on the merged parents."""
    children = {j["child"] for j in joints}
    roots = [n for n in bodies if n not in children]
    if len(roots) != 1:
        raise ValueError(f"URDF must have one root link, found {roots}")
    hinges = [j for j in joints if j["type"] in ("revolute", "continuous")]
    fixed = [j for j in joints if j["type"] == "fixed"]
    other = [j for j in joints if j["type"] not in ("revolute", "continuous", "fixed")]
    if other:
        raise ValueError(f"unsupported joint types: {sorted({j['type'] for j in other})}")
    by_child = {j["child"]: j for j in joints}

    def depth(link):
        d = 0
        while link in by_child:
            link, d = by_child[link]["parent"], d + 1
        return d

    for fj in sorted(fixed, key=lambda j: -depth(j["child"])):
        parent, child, p, R = fj["parent"], fj["child"], fj["p"], fj["R"]
        bodies[parent].absorb(bodies.pop(child), p, R)
        for j in joints:  # joints hanging from the merged child now hang from its parent
            if j["parent"] == child:
                j["parent"], j["p"], j["R"] = parent, p + R @ j["p"], R @ j["R"]
    return roots[0], hinges


def _inertial(b: _Body) -> Inertial:
    I = b.inertia
    return Inertial(b.mass, tuple(float(v) for v in b.com),
                    (float(I[0, 0]), float(I[1, 1]), float(I[2, 2]), float(I[0, 1]), float(I[0, 2]), float(I[1, 2])))


def _geoms(b: _Body, sole: Geom | None) -> tuple[Geom, ...]:
    out = [replace(g, xyz=tuple(float(v) for v in p), rpy=_rpy(R)) for p, R, g in b.visuals if g.kind == "mesh"]
    if sole is not None:
        out.append(sole)
    return tuple(out)


def _sole_box(b: _Body, foot: str, how: str) -> tuple[Geom, tuple[float, float, float]]:
    """The foot's contact box and its sole point (the foot origin's projection on the bottom face) in
    the foot frame.

    how: ``"spheres"``: the box around the foot's collision spheres (bottom at their lowest point);
    ``"box"``: the foot's lowest collision box as it is."""
    if how == "spheres":
        pts = np.array([p for p, _, g in b.collisions if g.kind == "sphere"])
        rad = max(g.size[0] for _, _, g in b.collisions if g.kind == "sphere")
        if len(pts) < 3:
            raise ValueError(f"{foot}: need >= 3 contact spheres for a sole, found {len(pts)}")
        lo, hi = pts.min(0) - rad, pts.max(0) + rad
        thick = 2 * rad
        size = (hi[0] - lo[0], hi[1] - lo[1], thick)
        centre = ((hi[0] + lo[0]) / 2, (hi[1] + lo[1]) / 2, lo[2] + thick / 2)
    else:
        boxes = [(p, R, g) for p, R, g in b.collisions if g.kind == "box"]
        if not boxes:
            raise ValueError(f"{foot}: no collision box")
        p, R, g = min(boxes, key=lambda t: t[0][2])
        if not np.allclose(R, np.eye(3)):
            raise ValueError(f"{foot}: the sole box must be axis-aligned with the foot frame")
        size, centre = g.size, tuple(p)
    geom = Geom("box", tuple(float(v) for v in size), tuple(float(v) for v in centre))
    sole = (0.0, 0.0, float(centre[2] - size[2] / 2))  # the ankle's projection on the sole plane
    return geom, sole


@dataclass(frozen=True)
class HumanoidSpec:
    """How to read one ``example-robot-data`` humanoid: URDF path (relative to :func:`robots_dir`),
    the two foot links and how their soles are given, joint groups by name prefix or substring, the
    IMU frame, poses [rad] by joint name (unnamed joints 0)."""

    name: str
    urdf: str
    feet: tuple[str, str]
    sole_from: str
    legs: tuple[tuple[str, ...], tuple[str, ...]]  # left / right leg joints, hip to ankle
    arms: tuple[str, ...]
    head: tuple[str, ...]
    imu_frame: str | None
    crouch: dict
    stand: dict


G1 = HumanoidSpec(
    name="g1", urdf="g1_description/urdf/g1_29dof_rev_1_0.urdf",
    feet=("left_ankle_roll_link", "right_ankle_roll_link"), sole_from="spheres",
    legs=tuple(tuple(f"{s}_{j}_joint" for j in ("hip_pitch", "hip_roll", "hip_yaw", "knee", "ankle_pitch",
                                                 "ankle_roll")) for s in ("left", "right")),
    arms=tuple(f"{s}_{j}_joint" for s in ("left", "right") for j in ("shoulder_pitch", "shoulder_roll", "shoulder_yaw",
                                                                     "elbow", "wrist_roll", "wrist_pitch",
                                                                     "wrist_yaw")),
    head=(), imu_frame="imu_in_pelvis",
    # Unitree's default joint angles of the G1 (unitree_rl_gym ``g1_config.py``: hip pitch -0.1,
    # knee 0.3, ankle pitch -0.2) deepened to a walking crouch; elbows bent like its stand.
    crouch={**{f"{s}_hip_pitch_joint": -0.35 for s in ("left", "right")},
            **{f"{s}_knee_joint": 0.7 for s in ("left", "right")},
            **{f"{s}_ankle_pitch_joint": -0.35 for s in ("left", "right")},
            "left_shoulder_roll_joint": 0.2, "right_shoulder_roll_joint": -0.2,
            "left_elbow_joint": 0.9, "right_elbow_joint": 0.9},
    stand={**{f"{s}_hip_pitch_joint": -0.1 for s in ("left", "right")},
           **{f"{s}_knee_joint": 0.3 for s in ("left", "right")},
           **{f"{s}_ankle_pitch_joint": -0.2 for s in ("left", "right")},
           "left_shoulder_roll_joint": 0.2, "right_shoulder_roll_joint": -0.2,
           "left_elbow_joint": 0.9, "right_elbow_joint": 0.9},
)

TALOS = HumanoidSpec(
    name="talos", urdf="talos_data/robots/talos_reduced_box.urdf",
    feet=("leg_left_6_link", "leg_right_6_link"), sole_from="box",
    legs=tuple(tuple(f"leg_{s}_{i}_joint" for i in range(1, 7)) for s in ("left", "right")),
    arms=tuple(f"arm_{s}_{i}_joint" for s in ("left", "right") for i in range(1, 8))
    + ("gripper_left_joint", "gripper_right_joint"),
    head=("head_1_joint", "head_2_joint"), imu_frame=None,
    # PAL's "half_sitting" (talos_data/srdf/talos.srdf in example-robot-data): legs 3/4/5 =
    # hip pitch, knee, ankle pitch; arms 1/2/4 = shoulder, shoulder roll, elbow.
    crouch={**{f"leg_{s}_3_joint": -0.411354 for s in ("left", "right")},
            **{f"leg_{s}_4_joint": 0.859395 for s in ("left", "right")},
            **{f"leg_{s}_5_joint": -0.448041 for s in ("left", "right")},
            "arm_left_1_joint": 0.25847, "arm_left_2_joint": 0.173046, "arm_left_4_joint": -0.525366,
            "arm_right_1_joint": -0.25847, "arm_right_2_joint": -0.173046, "arm_right_4_joint": -0.525366},
    stand={**{f"leg_{s}_3_joint": -0.2 for s in ("left", "right")},
           **{f"leg_{s}_4_joint": 0.4 for s in ("left", "right")},
           **{f"leg_{s}_5_joint": -0.2 for s in ("left", "right")},
           "arm_left_1_joint": 0.25847, "arm_left_2_joint": 0.173046, "arm_left_4_joint": -0.525366,
           "arm_right_1_joint": -0.25847, "arm_right_2_joint": -0.173046, "arm_right_4_joint": -0.525366},
)

SPECS = {"g1": G1, "talos": TALOS}


def _family(name: str) -> str:
    """Joint family: the name without its side (``left_knee_joint`` and ``right_knee_joint`` -> one)."""
    return name.replace("left", "*").replace("right", "*")


def _gains(robot: RobotModel, physics_dt: float) -> dict[str, tuple[float, float]]:
    """Per-joint (kp, kd) by the rule of the module docstring (MuJoCo mass matrix, crouch pose,
    fixed and floating base; bounds :data:`KP_BOUND`, :data:`KD_BOUND`)."""
    import mujoco  # lazy: robots stays importable without a physics engine (walk_engine's arrow)

    inertia = {n: math.inf for n in robot.joint_names}
    for floating in (False, True):
        spec = mujoco.MjSpec.from_string(robot.urdf())
        if floating:
            spec.compiler.fusestatic = False
            spec.body(robot.root).add_freejoint()
        model = spec.compile()
        data = mujoco.MjData(model)
        for n, v in zip(robot.joint_names, robot.pose("crouch")):
            data.qpos[model.jnt_qposadr[model.joint(n).id]] = v
        mujoco.mj_forward(model, data)
        M = np.zeros((model.nv, model.nv))
        mujoco.mj_fullM(model, data, M)
        inv_diag = np.diag(np.linalg.inv(M))
        for n in robot.joint_names:
            inertia[n] = min(inertia[n], 1.0 / inv_diag[model.jnt_dofadr[model.joint(n).id]])
    fam_I: dict[str, float] = {}
    for n in robot.joint_names:
        fam_I[_family(n)] = min(fam_I.get(_family(n), math.inf), inertia[n])
    out = {}
    for j in robot.joints:
        I = fam_I[_family(j.name)]
        kp = min(j.effort / SATURATING_ERROR, KP_BOUND * I / physics_dt ** 2)
        kd = min(2.0 * DAMPING_RATIO * math.sqrt(kp * I), KD_BOUND * I / physics_dt)
        out[j.name] = (float(f"{kp:.4g}"), float(f"{kd:.4g}"))
    return out


def _root_height(robot: RobotModel, pose: str) -> float:
    """Height [m] of the root origin above the lower sole in ``pose`` (MuJoCo kinematics)."""
    import mujoco  # lazy: see _gains

    spec = mujoco.MjSpec.from_string(robot.urdf())
    spec.compiler.fusestatic = False  # keep the root body (the URDF import welds it to the world)
    for name, fr in robot.frames.items():
        spec.body(fr.link).add_site(name=name, pos=list(fr.offset))
    model = spec.compile()
    data = mujoco.MjData(model)
    for n, v in zip(robot.joint_names, robot.pose(pose)):
        data.qpos[model.jnt_qposadr[model.joint(n).id]] = v
    mujoco.mj_kinematics(model, data)
    z = min(data.site_xpos[model.site(s).id][2] for s in ("l_sole", "r_sole"))
    return float(data.xpos[model.body(robot.root).id][2] - z)


def load_humanoid(spec: HumanoidSpec, physics_dt: float = PHYSICS_DT) -> RobotModel:
    """Build the :class:`RobotModel` of an ``example-robot-data`` humanoid (see the module docstring).

    Raises:
        ModuleNotFoundError: ``example-robot-data`` is not installed.
        ValueError: the URDF has no single root, unsupported joint types, or feet without a sole.
    """
    base = robots_dir()
    path = os.path.join(base, spec.urdf)
    bodies, joints = _parse(path, base)
    root, hinges = _merge_fixed(bodies, joints)
    soles = {}
    for foot, frame in zip(spec.feet, ("l_sole", "r_sole")):
        soles[foot] = _sole_box(bodies[foot], foot, spec.sole_from) + (frame,)
    frames = {}
    for foot, (_, point, frame) in soles.items():
        frames[frame] = Frame(foot, point)
    imu = (0.0, 0.0, 0.0)
    if spec.imu_frame is not None:
        if spec.imu_frame not in bodies[root].frames:
            raise ValueError(f"IMU frame {spec.imu_frame!r} is not on the root link {root!r}")
        imu = tuple(float(v) for v in bodies[root].frames[spec.imu_frame][0])
    frames["gyro"] = Frame(root, imu)
    frames["accel"] = Frame(root, imu)
    specs = []
    for j in hinges:
        lo, hi, effort, vel = j["limit"] if j["limit"] else (-math.pi, math.pi, 0.0, 0.0)
        if effort <= 0:
            raise ValueError(f"joint {j['name']}: URDF gives no effort limit")
        child = bodies[j["child"]]
        sole = soles.get(j["child"], (None,))[0]
        specs.append(JointSpec(j["name"], j["parent"], j["child"], tuple(float(v) for v in j["p"]), j["axis"],
                               lo, hi, effort, vel, 0.0, 0.0, _inertial(child), _geoms(child, sole),
                               rpy=_rpy(j["R"])))
    names = [s.name for s in specs]
    missing = [n for n in spec.legs[0] + spec.legs[1] + spec.arms + spec.head if n not in names]
    if missing:
        raise ValueError(f"{spec.name}: joints not in the URDF: {missing}")
    groups = {"legs": spec.legs[0] + spec.legs[1], "left_leg": spec.legs[0], "right_leg": spec.legs[1],
              "arms": spec.arms, "head": spec.head}
    poses = {"zero": {}, "stand": dict(spec.stand), "crouch": dict(spec.crouch)}

    def model(joint_specs, fall=0.2, hang=1.0):
        return RobotModel(spec.name, tuple(joint_specs), root=root, root_inertial=_inertial(bodies[root]),
                          root_geoms=_geoms(bodies[root], None), frames=frames, poses=poses, fall_height=fall,
                          hang_height=hang, group_names=groups, source=f"example-robot-data: {spec.urdf}")

    draft = model(specs)
    gains = _gains(draft, physics_dt)
    specs = [replace(s, kp=gains[s.name][0], kd=gains[s.name][1]) for s in specs]
    draft = model(specs)
    fall = FALL_HEIGHT_FRACTION * _root_height(draft, "crouch")
    hang = _root_height(draft, "zero") + 0.3
    return model(specs, round(fall, 3), round(hang, 3))


@functools.lru_cache(maxsize=None)
def unitree_g1() -> RobotModel:
    """Unitree G1 (29 hinges) from ``example-robot-data``. Cached: treat it as read-only."""
    return load_humanoid(G1)


@functools.lru_cache(maxsize=None)
def pal_talos() -> RobotModel:
    """PAL Talos (``talos_reduced_box``, 32 hinges) from ``example-robot-data``. Cached: read-only."""
    return load_humanoid(TALOS)
