"""Logging recordings into Rerun: one subtree per recording, the default blueprint, the legend.

The entity layout is described in :mod:`experiments.viz` (the package docstring).
"""

from __future__ import annotations

import contextlib
import math
import os
import shutil
import sys
import time
from collections.abc import Mapping

import numpy as np

from common.files import atomic_path
from common.spatial import quat_from_rpy, quat_rotate
from envs.recording import Recording, RecordingError
from experiments.viz.inputs import _PART, check_recording, sanitize_label
from experiments.viz.kinematics import (_NAO_SOLE_BOX, _NAO_SOLE_CENTER, _measured_cop, _robot_scale, _sole_geometry,
                                        _xyzw, link_poses)
from experiments.viz.style import PALETTE, STEP_TIMELINE, TIMELINE, WORLD_COLORS, _color, _pick_color
from experiments.viz.terrain import _ground_z, terrain_for, terrain_mesh
from robots import RobotModel
from terrain import Heightfield

#: Footstep boxes: the NAO sole (robots/nao.py), 5 mm thick; other robots' footsteps use their own
#: foot's collision box (:func:`experiments.viz.kinematics._sole_geometry`).
SOLE_BOX = _NAO_SOLE_BOX
SOLE_CENTER = _NAO_SOLE_CENTER  # sole centre ahead of / outward of the sole frame [m]
#: Default 3D camera for the NAO: this offset [m] from the point it looks at (behind-left, above);
#: scaled by the robot's size relative to the NAO's for other robots.
EYE_OFFSET = np.array([-0.75, -1.15, 0.55])


class _Logger:
    """Sends one recording's entities; counts rows per entity for the summary."""

    def __init__(self, stream, label: str, rec: Recording):
        import rerun as rr  # lazy: rerun

        self.rr = rr
        self.stream = stream
        self.root = "/" + label
        self.rows: dict[str, int] = {}
        t = np.asarray(rec.t, float)
        self.index = [rr.TimeColumn(TIMELINE, duration=t), rr.TimeColumn(STEP_TIMELINE, sequence=np.arange(len(t)))]
        self.n = len(t)

    def columns(self, path: str, columns, index=None, n=None) -> None:
        path = f"{self.root}/{path}"
        self.stream.send_columns(path, indexes=index or self.index, columns=columns)
        self.rows[path] = self.rows.get(path, 0) + (n if n is not None else self.n)

    def static(self, path: str, archetype) -> None:
        self.stream.log(f"{self.root}/{path}" if path else self.root, archetype, static=True)

    def scalar(self, path: str, values: np.ndarray, name: str, color, width: float = 1.5) -> None:
        rr = self.rr
        self.static(path, rr.SeriesLines(names=[name], colors=[color], widths=[width]))
        self.columns(path, rr.Scalars.columns(scalars=np.asarray(values, np.float64)))

    def points(self, path: str, P: np.ndarray, color, radius: float) -> None:
        """A moving marker: one row per time, an empty row where P is NaN."""
        rr = self.rr
        ok = np.all(np.isfinite(P), axis=1)
        # static styling only: static positions would shadow the time-varying ones
        self.static(path, rr.Points3D.from_fields(radii=[radius], colors=[color]))
        self.columns(path, rr.Points3D.columns(positions=P[ok]).partition(ok.astype(np.int64)))


def _primitives(rr, gs, col, link: str):
    """One Rerun archetype for primitives ``gs`` of one kind (box, capsule, sphere) in the link frame.

    Raises:
        ValueError: an unknown kind.
    """
    kind = gs[0].kind
    qs = [_xyzw(quat_from_rpy(*g.rpy)) for g in gs]
    if kind == "box":
        return rr.Boxes3D(centers=[g.xyz for g in gs], half_sizes=[[s / 2 for s in g.size] for g in gs],
                          quaternions=qs, colors=[col] * len(gs), fill_mode="solid")
    if kind == "capsule":
        # URDF capsule: centred, cylinder of `length` along local z; Rerun: from 0 to +length along z.
        starts = [np.asarray(g.xyz) + quat_rotate(quat_from_rpy(*g.rpy), np.array([0.0, 0.0, -g.size[1] / 2]))
                  for g in gs]
        return rr.Capsules3D(lengths=[g.size[1] for g in gs], radii=[g.size[0] for g in gs], translations=starts,
                             quaternions=qs, colors=[col] * len(gs), fill_mode="solid")
    if kind == "sphere":
        return rr.Ellipsoids3D(centers=[g.xyz for g in gs], half_sizes=[[g.size[0]] * 3 for g in gs],
                               colors=[col] * len(gs), fill_mode="solid")
    raise ValueError(f"unknown geometry kind {kind!r} on link {link!r}")


#: Mesh file formats Rerun's ``Asset3D`` draws (rerun-sdk 0.41: ``MediaType.guess_from_path``).
MESH_MEDIA_TYPES = ("model/stl", "model/obj", "model/gltf-binary", "model/gltf+json")


def _log_meshes(L: "_Logger", rr, link: str, meshes, color) -> list[str]:
    """Log a link's visual meshes, static, at ``robot/<link>/mesh/<file stem>``: a Transform3D with
    the geom's pose in the link frame (``xyz`` [m], ``rpy`` [rad], ``size`` = scale x, y, z) and an
    ``Asset3D`` of the file (its bytes are embedded; tinted ``color``). Returns the mesh files not
    drawn (missing, or a format Rerun cannot read, e.g. Collada)."""
    from rerun.components import MediaType  # lazy: rerun

    skipped, used = [], set()
    for g in meshes:
        media = MediaType.guess_from_path(g.mesh) if g.mesh else None
        if not g.mesh or not os.path.isfile(g.mesh) or media is None or str(media) not in MESH_MEDIA_TYPES:
            skipped.append(str(g.mesh))
            continue
        stem = _PART.sub("_", os.path.splitext(os.path.basename(g.mesh))[0]).strip("_") or "mesh"
        name, k = stem, 2
        while name in used:
            name, k = f"{stem}_{k}", k + 1
        used.add(name)
        path = f"robot/{link}/mesh/{name}"
        L.static(path, rr.Transform3D(translation=g.xyz, quaternion=_xyzw(quat_from_rpy(*g.rpy)), scale=g.size))
        L.static(path, rr.Asset3D(path=g.mesh, media_type=media, albedo_factor=color))
    return skipped


def log_recording(stream, label: str, rec: Recording, terrain: Heightfield | None = None,
                  terrain_note: str = "", color=None) -> dict[str, int]:
    """Log one recording under ``/<label>`` of an open ``rerun.RecordingStream``.

    Args:
        stream: the Rerun recording stream (e.g. from :func:`log_rollouts_to_rrd`).
        label: entity path of the subtree (already sanitized, without leading '/').
        rec: a checked recording (see :func:`check_recording`); its robot (``rec.robot``) is drawn
            from the model's primitives and, for the G1 and Talos, its visual meshes.
        terrain: the heightfield it ran on (None: flat plane at z = 0).
        terrain_note: where the terrain came from (shown in the events log).
        color: base RGB colour (default by world).

    Returns:
        {entity path: number of time-varying rows logged}.

    Raises:
        RecordingError: malformed ``footsteps`` metadata (message names the label).
        ValueError: a robot geometry kind other than box, capsule, sphere or mesh.
    """
    import rerun as rr  # lazy: rerun

    world = str(rec.meta.get("world", "unknown"))
    color = tuple(color or WORLD_COLORS.get(world, PALETTE[0]))
    L = _Logger(stream, label, rec)
    # scene: the subtree's axes and its ground
    L.static("", rr.ViewCoordinates.RIGHT_HAND_Z_UP)
    L.static("terrain", rr.Mesh3D(**terrain_mesh(terrain)))
    links, pos, quat, grounded = link_poses(rec)
    skipped_meshes = _log_robot(L, rec.robot, links, pos, quat, color)
    balance = _log_balance(L, rec, terrain, links, pos, quat, color)
    _log_footsteps(L, label, rec, terrain)
    start_msg = _start_message(rec, world, terrain_note, grounded, skipped_meshes)
    _log_events(L, rec, terrain, pos, start_msg)
    _log_time_series(L, label, rec, balance, color)
    return L.rows


def _log_robot(L: _Logger, robot: RobotModel, links: list[str], pos: np.ndarray, quat: np.ndarray,
               color) -> list[str]:
    """Log every link's pose (``pos`` (T, links, 3) [m], ``quat`` (T, links, 4) w, x, y, z) at
    ``robot/<link>``, its primitives (the soles' links darker) and its meshes; returns the mesh files
    not drawn (see :func:`_log_meshes`).

    Raises:
        ValueError: a geometry kind other than box, capsule, sphere or mesh.
    """
    rr = L.rr
    xyzw = _xyzw(quat)
    geoms = {robot.root: robot.root_geoms, **{j.child: j.geoms for j in robot.joints}}
    body_col = _color(color, 0.35)
    foot_col = _color(color, 0.0)
    mesh_col = _color(color, 0.55)
    feet = {robot.frames[f].link for f in ("l_sole", "r_sole")}  # their boxes: the soles, darker
    skipped_meshes: list[str] = []
    for i, link in enumerate(links):
        L.columns(f"robot/{link}", rr.Transform3D.columns(translation=pos[:, i], quaternion=xyzw[:, i]))
        gs = geoms.get(link, ())
        prims = [g for g in gs if g.kind != "mesh"]
        if prims:
            col = foot_col if link in feet else body_col
            kinds = list(dict.fromkeys(g.kind for g in prims))
            for kind in kinds:  # one kind: "geom" (the NAO); several: "geom/<kind>"
                path = f"robot/{link}/geom" if len(kinds) == 1 else f"robot/{link}/geom/{kind}"
                L.static(path, _primitives(rr, [g for g in prims if g.kind == kind], col, link))
        skipped_meshes += _log_meshes(L, rr, link, [g for g in gs if g.kind == "mesh"], mesh_col)
    return skipped_meshes


def _log_balance(L: _Logger, rec: Recording, terrain: Heightfield | None, links: list[str], pos: np.ndarray,
                 quat: np.ndarray, color) -> dict[str, np.ndarray]:
    """Log the balance markers the recording has: measured CoM (and its trail), measured CoP, planned
    CoM (and its trail) and ZMP reference (on the ground). Returns {``com``, ``cop``, ``plan_com``,
    ``zmp_ref``: (T, 3) [m] world positions} for those logged."""
    rr = L.rr
    robot = rec.robot
    balance: dict[str, np.ndarray] = {}
    if rec.has("gt.com"):
        com = rec.group("gt.com")
        balance["com"] = com
        L.points("com", com, _color(color, 0.0), 0.012)
        L.static("com_trail", rr.LineStrips3D([com], colors=[_color(color, 0.3)], radii=[0.002]))
    cop = _measured_cop(rec, robot, links, pos, quat)
    if np.isfinite(cop).any():
        balance["cop"] = cop
        L.points("cop", cop, [230, 30, 30], 0.010)
    if "plan.com.x" in rec.columns:
        pc = np.column_stack([rec.columns["plan.com.x"], rec.columns["plan.com.y"],
                              rec.columns.get("plan.com.z", np.full(len(rec), np.nan))])
        if not np.isfinite(pc[:, 2]).any():
            pc[:, 2] = balance["com"][:, 2] if "com" in balance else 0.26 * _robot_scale(robot)
        balance["plan_com"] = pc
        L.points("plan/com", pc, [250, 200, 0], 0.010)
        L.static("plan/com_trail", rr.LineStrips3D([pc[np.all(np.isfinite(pc), 1)]], colors=[[250, 200, 0]],
                                                   radii=[0.0015]))
    if "plan.zmp.x" in rec.columns:
        zx, zy = rec.columns["plan.zmp.x"], rec.columns["plan.zmp.y"]
        pz = np.column_stack([zx, zy, _ground_z(terrain, zx, zy) + 0.002])
        balance["zmp_ref"] = pz
        L.points("plan/zmp", pz, [0, 200, 200], 0.008)
    return balance


def _footstep_fields(label: str, steps) -> tuple:
    """The columns of ``footsteps`` metadata: x, y [m], yaw [rad] (S,), sides ("L"/"R"), start and end
    times [s] (S,; an open end is inf).

    Raises:
        RecordingError: a malformed entry (message names the label).
    """
    try:
        fx = np.array([float(s["x"]) for s in steps])
        fy = np.array([float(s["y"]) for s in steps])
        fyaw = np.array([float(s.get("yaw", 0.0)) for s in steps])
        side = [str(s.get("side", "L")) for s in steps]
        t0 = np.array([float(s.get("t_start") or 0.0) for s in steps])
        t1 = np.array([math.inf if s.get("t_end") is None else float(s["t_end"]) for s in steps])
    except (KeyError, TypeError, ValueError) as exc:
        raise RecordingError(f"{label}: metadata 'footsteps' must be a list of {{x, y, yaw, side, t_start, "
                             f"t_end}}: {exc}") from None
    return fx, fy, fyaw, side, t0, t1


def _log_footsteps(L: _Logger, label: str, rec: Recording, terrain: Heightfield | None) -> None:
    """Log the planned footsteps (``meta["footsteps"]``), static wireframe boxes of the robot's sole
    on the ground at ``plan/footsteps``, and solid copies while each is in use at
    ``plan/footsteps/active``; nothing when there are none.

    Raises:
        RecordingError: malformed ``footsteps`` metadata (message names the label).
    """
    steps = rec.meta.get("footsteps") or []
    if not steps:
        return
    rr = L.rr
    fx, fy, fyaw, side, t0, t1 = _footstep_fields(label, steps)
    sole_box, sole_center = _sole_geometry(rec.robot)
    sgn = np.array([1.0 if s == "L" else -1.0 for s in side])
    cx = fx + np.cos(fyaw) * sole_center[0] - np.sin(fyaw) * sgn * sole_center[1]
    cy = fy + np.sin(fyaw) * sole_center[0] + np.cos(fyaw) * sgn * sole_center[1]
    cz = _ground_z(terrain, cx, cy) + sole_box[2] / 2
    centers = np.column_stack([cx, cy, cz])
    qs = np.column_stack([np.zeros((len(steps), 2)), np.sin(fyaw / 2), np.cos(fyaw / 2)])
    cols = np.array([[60, 60, 230] if s == "L" else [230, 60, 60] for s in side], np.uint8)
    half = np.tile(np.asarray(sole_box) / 2, (len(steps), 1))
    labels = [f"{s}{k}" for k, s in enumerate(side)]
    L.static("plan/footsteps", rr.Boxes3D(centers=centers, half_sizes=half, quaternions=qs, colors=cols,
                                          labels=labels, show_labels=False, fill_mode="MajorWireframe"))
    active = (t0[None, :] <= rec.t[:, None]) & (rec.t[:, None] < t1[None, :])  # (T, S)
    _, idx = np.nonzero(active)
    L.static("plan/footsteps/active", rr.Boxes3D.from_fields(fill_mode="solid"))
    L.columns("plan/footsteps/active", rr.Boxes3D.columns(
        centers=centers[idx], half_sizes=half[idx], quaternions=qs[idx], colors=cols[idx]
    ).partition(active.sum(1).astype(np.int64)))


def _start_message(rec: Recording, world: str, terrain_note: str, grounded: bool, skipped_meshes: list[str]) -> str:
    """The events log's first line: world, rows, control period, seed, profile, terrain, and what is
    not drawn as recorded (no ground-truth base pose, mesh files)."""
    seed, prof = rec.meta.get("seed"), rec.meta.get("profile")
    tinfo = rec.meta.get("terrain") or {}
    return (f"{world} rollout: {len(rec)} rows x {float(rec.meta['control_dt']) * 1e3:g} ms, seed {seed}"
            + (f", profile {prof}" if prof else "") + f", terrain {tinfo.get('name', 'flat')}"
            + (f" ({terrain_note})" if terrain_note else "")
            + ("" if grounded else "; no ground-truth base pose: robot drawn upright at the origin")
            + (f"; {len(skipped_meshes)} mesh file(s) not drawn (missing or not STL/OBJ/glTF): "
               f"{', '.join(skipped_meshes[:3])}" if skipped_meshes else ""))


def _log_events(L: _Logger, rec: Recording, terrain: Heightfield | None, pos: np.ndarray, start_msg: str) -> None:
    """Log the events text log (``start_msg`` at the first row; a warning at the fall) and, for a fall,
    a labelled marker on the ground under the last base position (``pos`` (T, links, 3) [m])."""
    rr = L.rr
    T = len(rec)
    texts, levels, times = [start_msg], ["INFO"], [float(rec.t[0])]
    if rec.fell:
        ft = rec.meta.get("fall_time")
        ft = float(ft) if ft is not None else float(rec.t[-1])
        reason = rec.meta.get("fall_reason") or "unknown"
        base = pos[-1, 0]
        p = [float(base[0]), float(base[1]), float(_ground_z(terrain, base[0], base[1])) + 0.03]
        msg = f"fell at t = {ft:.2f} s: {reason}"
        fidx = [rr.TimeColumn(TIMELINE, duration=[ft]), rr.TimeColumn(STEP_TIMELINE, sequence=[T])]
        L.static("fall", rr.Points3D.from_fields(radii=[0.05], colors=[[230, 0, 0]], show_labels=True))
        L.columns("fall", rr.Points3D.columns(positions=[p], labels=[msg]), index=fidx, n=1)
        texts.append(msg)
        levels.append("WARN")
        times.append(ft)
    L.columns("events", rr.TextLog.columns(text=texts, level=levels),
              index=[rr.TimeColumn(TIMELINE, duration=times),
                     rr.TimeColumn(STEP_TIMELINE, sequence=[0] + [T] * (len(times) - 1))], n=len(times))


def _log_time_series(L: _Logger, label: str, rec: Recording, balance: Mapping[str, np.ndarray], color) -> None:
    """Log the plotted series under ``ts/``: each leg joint's commanded, applied and measured angle
    [rad], gyro [rad/s], torso roll and pitch [rad], foot forces [N], and x, y [m] of the ``balance``
    markers (from :func:`_log_balance`)."""
    robot = rec.robot
    idx = {n: i for i, n in enumerate(robot.joint_names)}
    q = rec.group("q")
    cmd = robot.expand_action(rec.group("cmd"))
    app = robot.expand_action(rec.group("app")) if rec.has("app") else None
    shades = {"q": (0.0, 2.0), "app": (0.35, 1.5), "cmd": (0.6, 1.0)}
    for j in robot.groups["legs"]:
        k = idx[j]
        for kind, arr in (("cmd", cmd), ("app", app), ("q", q)):
            if arr is None:
                continue
            mix, width = shades[kind]
            L.scalar(f"ts/joints/{j}/{kind}", arr[:, k], f"{label} {kind}", _color(color, mix), width)
    for group, names in (("gyro", ("x", "y", "z")), ("angle", ("roll", "pitch")), ("fsr", ("L", "R"))):
        if rec.has(group):
            arr = rec.group(group)
            for i, nm in enumerate(names):
                L.scalar(f"ts/{group}/{nm}", arr[:, i], f"{label} {group}.{nm}", _color(color, 0.0))
    styles = {"com": (0.0, 2.0), "cop": (-0.45, 1.0), "plan_com": (0.45, 1.5), "zmp_ref": (0.75, 1.0)}
    for key, arr in balance.items():
        mix, width = styles[key]
        for i, ax in enumerate("xy"):
            L.scalar(f"ts/balance/{ax}/{key}", arr[:, i], f"{label} {key} {ax}", _color(color, mix), width)


def build_blueprint(labels: list[str], robot: RobotModel, worlds: Mapping[str, str] | None = None,
                    centers: Mapping[str, tuple[float, float, float]] | None = None, active=(0, 0)):
    """The default layout: 3D views side by side on top, compare plots below (one timeline).

    Top: one 3D view per label (origin ``/<label>``), its camera looking at ``centers[label]``
    (world [m], default 0.2 m above the origin; e.g. the middle of the torso path) from behind-left,
    distance and default height scaled by ``robot``'s size relative to the NAO's; labels
    of the same world (``worlds[label]``) share a column as tabs; a second tab overlays all robots
    on the first label's terrain. ``active``: the initially shown (3D tab, plot tab) indices.
    Bottom tabs: left leg and right leg (one plot per joint: every label's cmd/app/q), IMU (gyro,
    roll, pitch), balance (x and y of CoM, CoP, planned CoM, ZMP reference), feet (FSR) and events.

    Returns:
        ``rerun.blueprint.Blueprint``.
    """
    import rerun.blueprint as rrb  # lazy: rerun

    worlds = dict(worlds or {})
    centers = dict(centers or {})
    scale = _robot_scale(robot)  # camera distance and height follow the robot's size (1.0: the NAO)

    def eye(label):
        c = np.asarray(centers.get(label, (0.0, 0.0, 0.2 * scale)), float)
        return rrb.EyeControls3D(position=tuple(c + EYE_OFFSET * scale), look_target=tuple(c))

    def view3d(label):
        return rrb.Spatial3DView(origin=f"/{label}", name=label, contents=[f"/{label}/**", f"- /{label}/ts/**"],
                                 eye_controls=eye(label), line_grid=rrb.LineGrid3D(visible=False))

    by_world: dict[str, list[str]] = {}
    for lab in labels:
        by_world.setdefault(worlds.get(lab, lab.split("/")[0]), []).append(lab)
    columns = [view3d(labs[0]) if len(labs) == 1 else rrb.Tabs(*[view3d(x) for x in labs], name=w)
               for w, labs in by_world.items()]
    side = rrb.Horizontal(*columns, name="side by side")
    overlay = rrb.Spatial3DView(
        origin="/", name="overlay", eye_controls=eye(labels[0]), line_grid=rrb.LineGrid3D(visible=False),
        contents=[f"/{labels[0]}/terrain"] + [f"/{x}/robot/**" for x in labels] + [f"/{x}/plan/**" for x in labels]
        + [f"/{x}/fall" for x in labels])

    def plots(suffix: str, name: str, lines_per_label: int = 1):
        return rrb.TimeSeriesView(name=name, origin="/", contents=[f"/{x}/ts/{suffix}" for x in labels],
                                  plot_legend=rrb.PlotLegend(visible=len(labels) * lines_per_label <= 4))

    legs = lambda side_: rrb.Grid(*[plots(f"joints/{j}/**", f"{j} [rad]", 3) for j in robot.groups[side_]],
                                  grid_columns=3, name="left leg" if side_ == "left_leg" else "right leg")
    imu = rrb.Grid(*[plots(f"gyro/{a}", f"gyro {a} [rad/s]") for a in "xyz"],
                   plots("angle/roll", "torso roll [rad]"), plots("angle/pitch", "torso pitch [rad]"),
                   grid_columns=3, name="IMU")
    bal = rrb.Grid(plots("balance/x/**", "x: CoM, CoP, plan [m]", 4), plots("balance/y/**", "y: CoM, CoP, plan [m]", 4),
                   grid_columns=2, name="balance")
    feet = rrb.Grid(plots("fsr/L", "left foot force [N]"), plots("fsr/R", "right foot force [N]"), grid_columns=2,
                    name="feet")
    events = rrb.TextLogView(name="events", origin="/", contents=[f"/{x}/events" for x in labels])
    key = rrb.TextDocumentView(name="legend", origin="/legend")
    return rrb.Blueprint(
        rrb.Vertical(rrb.Tabs(side, overlay, name="3D", active_tab=active[0]),
                     rrb.Tabs(legs("left_leg"), legs("right_leg"), imu, bal, feet, events, key, name="plots",
                              active_tab=active[1]), row_shares=[3, 2]),
        collapse_panels=True)


#: Shown in the "legend" tab of the default blueprint.
LEGEND_MD = """# How to read this recording

* **3D** (one view per rollout, tab *overlay* puts all robots on one terrain): the robot from its
  recorded joint angles and ground-truth base pose; terrain coloured green (low) to sand (high).
  Yellow line and dot: planned CoM; cyan dot: ZMP reference; red dot: measured centre of pressure;
  wireframe boxes: planned footsteps (blue left, red right), solid while in use; big red dot with
  text: where and why the robot fell.
* **Joint plots** (one per leg joint, all rollouts): the world's colour (sim blue, real orange,
  grounded green) at three shades: measured `q` (thick, full colour), applied `app` (after
  grounding, medium), commanded `cmd` (thin, lightest). Hover a line to see its name.
* **IMU**: gyro [rad/s] and torso roll/pitch [rad]. **balance**: x and y [m] in the world's
  colour: measured CoM (thick), planned CoM (light), ZMP reference (lightest, steps), measured CoP
  (dark, thin). **feet**: foot normal forces [N]. **events**: start and fall messages.
* Timelines: `time` (seconds since reset, shared by all rollouts) and `step` (control step).
"""


def log_rollouts_to_rrd(recordings: Mapping[str, Recording], path: str | os.PathLike | None = None, *,
                        terrains: Mapping[str, Heightfield | None] | None = None, spawn: bool = False,
                        application_id: str = "sgatwalk", recording_id: str | None = None,
                        blueprint: bool = True) -> dict:
    """Log recordings side by side into one ``.rrd`` file (or a spawned viewer).

    This is the entry point for ``sgatwalk visualize`` and for ``sgatwalk optimize --rerun``
    (e.g. ``{"gen_005/best": rec, "gen_005/median": rec, "eval/real_seed_3": rec}``).

    Args:
        recordings: label -> recording, all of one robot (``meta["robot"]``: ``nao``, ``g1`` or
            ``talos``). A label becomes the entity path ``/<label>`` ('/' nests; characters outside
            [A-Za-z0-9_.-] become '_'); labels must stay distinct and none may be a prefix path of
            another.
        path: the ``.rrd`` to write (atomically: a temporary file, then rename); required unless
            ``spawn``.
        terrains: label -> heightfield (None = flat) for recordings whose terrain is known;
            others are regenerated with :func:`terrain_for`.
        spawn: open a Rerun viewer (``rerun`` on PATH) instead of writing a file.
        application_id, recording_id: Rerun ids (the viewer merges files of one recording id).
        blueprint: send :func:`build_blueprint`'s layout as the default blueprint.

    Returns:
        dict: ``path``, ``labels``, ``rows`` ({entity: time-varying rows}), ``notes`` ({label:
        terrain note}), ``log_seconds`` (building + sending, without the final flush),
        ``seconds`` (total), ``bytes`` (file size, 0 when spawning).

    Raises:
        ValueError: no recordings, clashing labels, no path, recordings of different robots;
            RecordingError (a ValueError) for a recording of an unknown robot, one whose columns are not
            its robot's, an empty or malformed one (message names the label).
    """
    import rerun as rr  # lazy: rerun

    if not recordings:
        raise ValueError("no recordings to visualize")
    if path is None and not spawn:
        raise ValueError("give a path for the .rrd file (or spawn=True)")
    labels, orig = _entity_labels(recordings)
    terrains = dict(terrains or {})
    robot = _common_robot(labels)
    t_start = time.perf_counter()
    stream = rr.RecordingStream(application_id, recording_id=recording_id)
    if not stream.is_enabled():
        raise ValueError("Rerun logging is disabled (environment variable RERUN=off?); unset it to write .rrd files")
    bp = _default_blueprint(labels, robot) if blueprint else None
    if spawn:
        _put_viewer_on_path()
    else:
        path = os.fspath(path)
    # a file is written to a temporary beside it and renamed when complete (common.files.atomic_path)
    with contextlib.nullcontext(None) if spawn else atomic_path(path, suffix=".rrd") as tmp:
        if spawn:
            stream.spawn(default_blueprint=bp)
        else:
            stream.save(tmp, default_blueprint=bp)
        try:
            rows, notes = _log_labelled(stream, labels, orig, terrains)
            t_log = time.perf_counter() - t_start
            stream.flush()
        finally:
            stream.disconnect()
    size = 0 if spawn else os.path.getsize(path)
    return {"path": None if spawn else path, "labels": list(labels), "rows": rows, "notes": notes,
            "log_seconds": t_log, "seconds": time.perf_counter() - t_start, "bytes": size}


def _entity_labels(recordings: Mapping[str, Recording]) -> tuple[dict[str, Recording], dict[str, str]]:
    """Check each recording and sanitize its label: ({entity label: recording}, {entity label: label
    as given}), in the order given.

    Raises:
        ValueError: two labels that map to one entity path, or one that is a prefix path of another;
            RecordingError (a ValueError) for a recording :func:`check_recording` refuses.
    """
    labels: dict[str, Recording] = {}
    orig: dict[str, str] = {}
    for lab, rec in recordings.items():
        s = sanitize_label(lab)
        if s in labels:
            raise ValueError(f"recording labels {orig[s]!r} and {lab!r} map to the same entity path /{s}")
        check_recording(rec, str(lab))
        labels[s] = rec
        orig[s] = lab
    keys = sorted(labels)
    for a, b in zip(keys, keys[1:]):
        if b.startswith(a + "/"):
            raise ValueError(f"label {orig[a]!r} is a prefix of {orig[b]!r}; rename one")
    return labels, orig


def _common_robot(labels: Mapping[str, Recording]) -> RobotModel:
    """The robot of every recording.

    Raises:
        ValueError: recordings of different robots.
    """
    robot = next(iter(labels.values())).robot
    others = {r.robot.name for r in labels.values()} - {robot.name}
    if others:
        raise ValueError(f"recordings of different robots ({robot.name} and {', '.join(sorted(others))}) cannot share "
                         "one view; visualize each robot's recordings separately")
    return robot


def _default_blueprint(labels: Mapping[str, Recording], robot: RobotModel):
    """:func:`build_blueprint` for these recordings: each world's label its own column, each camera
    looking at the middle of the base path's x and y extent (where the recording has ``gt.base``),
    0.2 m above the ground for the NAO, scaled by ``robot``'s size for others."""
    scale = _robot_scale(robot)
    centers = {}
    for k, r in labels.items():
        if r.has("gt.base"):
            b = r.group("gt.base")
            centers[k] = (0.5 * (b[:, 0].min() + b[:, 0].max()), 0.5 * (b[:, 1].min() + b[:, 1].max()), 0.2 * scale)
    return build_blueprint(list(labels), robot, {k: str(r.meta.get("world", k)) for k, r in labels.items()}, centers)


def _put_viewer_on_path() -> None:
    """Put this Python's ``bin`` folder on PATH when the ``rerun`` viewer is there and not on PATH (the
    viewer ships with rerun-sdk, next to python)."""
    venv_bin = os.path.dirname(sys.executable)
    if shutil.which("rerun") is None and os.path.exists(os.path.join(venv_bin, "rerun")):
        os.environ["PATH"] = venv_bin + os.pathsep + os.environ.get("PATH", "")


def _log_labelled(stream, labels: Mapping[str, Recording], orig: Mapping[str, str],
                  terrains: Mapping[str, Heightfield | None]) -> tuple[dict[str, int], dict[str, str]]:
    """Log the legend and every recording (:func:`log_recording`, colours picked per world) on its
    terrain: the one given in ``terrains`` (by entity label or label as given; None: flat) or else
    :func:`terrain_for`'s. Returns ({entity path: time-varying rows}, {entity label: terrain note}).

    Raises:
        RecordingError, ValueError: what :func:`log_recording` raises.
    """
    import rerun as rr  # lazy: rerun

    rows: dict[str, int] = {}
    notes: dict[str, str] = {}
    used: dict[str, int] = {}
    stream.log("/legend", rr.TextDocument(LEGEND_MD, media_type=rr.MediaType.MARKDOWN), static=True)
    for lab, rec in labels.items():
        if lab in terrains or orig[lab] in terrains:
            hf = terrains.get(lab, terrains.get(orig[lab]))
            note = "flat ground (plane at z = 0)" if hf is None else "the rollout's terrain"
        else:
            hf, note = terrain_for(rec)
        notes[lab] = note
        rows.update(log_recording(stream, lab, rec, hf, note, _pick_color(str(rec.meta.get("world", "")), used)))
    return rows, notes
