"""Rerun logging of rollouts: the robot in 3D, its terrain, time series, plan and fall, many worlds.

One :class:`envs.Recording` becomes one subtree ``/<label>`` of a Rerun recording; several
recordings (sim, real, grounded sim, trials of an optimisation run) share the ``time`` timeline and
are laid out side by side by :func:`build_blueprint`. Everything time-varying is sent with Rerun's
columnar API (``RecordingStream.send_columns``, one call per entity per rollout), so a 7.5 s
rollout (750 rows) logs in a few tens of milliseconds (``benchmarks/bench_rerun.py``).

Entity layout (``<label>`` is the world, e.g. ``sim``, or ``<world>/<name>`` when a world has
several recordings; all positions in the world frame [m], z up; every time-varying entity has one
row per recording row on the timelines ``time`` (duration, the recording's ``t`` [s]) and ``step``
(sequence, the row index), unless noted):

==========================================  ================  ===================================================
entity                                      archetype         content
==========================================  ================  ===================================================
``/<label>``                                ViewCoordinates   static: right-handed, z up
``/<label>/terrain``                        Mesh3D            static: the heightfield (MuJoCo's triangle diagonal)
                                                              or a flat 6 m x 3 m quad at z = 0
``/<label>/robot/<link>``                   Transform3D       world pose of each of the 25 links (own forward
                                                              kinematics from ``q.*`` and ``gt.base``/``gt.quat``)
``/<label>/robot/<link>/geom``              Boxes3D,          static: the link's primitives (``RobotModel`` spec),
                                            Capsules3D,       in the link frame
                                            Ellipsoids3D
``/<label>/com``                            Points3D          measured (ground-truth) CoM ``gt.com.*``
``/<label>/com_trail``                      LineStrips3D      static: the whole CoM path
``/<label>/cop``                            Points3D          measured centre of pressure on the ground: ``gt.cop``
                                                              or, without it, from ``fsr.*``/``cop.*`` and the
                                                              sole poses; an empty row when no foot touches
``/<label>/plan/com``                       Points3D          planned CoM ``plan.com.*`` (if present)
``/<label>/plan/zmp``                       Points3D          ZMP reference ``plan.zmp.*`` on the terrain (if present)
``/<label>/plan/com_trail``                 LineStrips3D      static: planned CoM path (if present)
``/<label>/plan/footsteps``                 Boxes3D           static: every planned footstep (metadata ``footsteps``)
``/<label>/plan/footsteps/active``          Boxes3D           the footsteps whose [t_start, t_end) holds t
``/<label>/fall``                           Points3D          one row at ``fall_time``: where (torso over the ground)
                                                              and why (label) the robot fell; absent if it did not
``/<label>/events``                         TextLog           start (world, seed, terrain ...) and fall messages
``/<label>/ts/joints/<joint>/{cmd,app,q}``  Scalars           commanded, applied (after grounding; absent when the
                                                              recording has no ``app.*``) and measured angle [rad]
                                                              of each of the 12 leg joints (``RHipYawPitch``'s
                                                              command is ``LHipYawPitch``'s: one motor)
``/<label>/ts/gyro/{x,y,z}``                Scalars           torso gyro [rad/s] (if present)
``/<label>/ts/angle/{roll,pitch}``          Scalars           torso roll/pitch estimate [rad] (if present)
``/<label>/ts/fsr/{L,R}``                   Scalars           foot normal force [N] (if present)
``/<label>/ts/balance/{x,y}/<quantity>``    Scalars           ``com``, ``cop``, ``plan_com``, ``zmp_ref`` [m]
``/legend``                                 TextDocument      static: how to read the views (markdown)
==========================================  ================  ===================================================

Diagnostics convention (optional, shown when present): columns ``plan.com.x|y|z`` (planned CoM,
world [m]), ``plan.zmp.x|y`` (ZMP reference), metadata ``footsteps``: a list of ``{"x", "y",
"yaw", "side" ("L"/"R"), "t_start", "t_end"}`` where (x, y, yaw) is the planned sole frame
(``l_sole``/``r_sole``: the ankle projected 45.11 mm down, world [m], [rad]).

Terrain heights are not stored in recordings; :func:`terrain_for` regenerates them from the
metadata (seed, effects) and checks the result against the recorded shape and min/max.

Sources: rerun-sdk 0.41 (https://rerun.io/docs, https://ref.rerun.io/docs/python/), quaternion order x, y, z, w for
Rerun and w, x, y, z in recordings.
"""

from __future__ import annotations

import contextlib
import math
import os
import re
import time
from collections.abc import Mapping

import numpy as np

from common.files import atomic_path
from common.spatial import quat_from_rpy, quat_mul, quat_rotate
from envs.recording import Recording, RecordingError
from robots import RobotModel
from terrain import Heightfield

#: Timelines: ``time`` (duration [s]) and ``step`` (row index).
TIMELINE = "time"
STEP_TIMELINE = "step"
#: Base colours (RGB) per world; other labels cycle through :data:`PALETTE`.
WORLD_COLORS = {"sim": (52, 120, 246), "real": (240, 120, 30), "grounded": (40, 170, 80)}
PALETTE = [(52, 120, 246), (240, 120, 30), (40, 170, 80), (200, 50, 160), (120, 90, 200), (30, 170, 190),
           (200, 170, 20), (150, 80, 40)]
#: Flat ground drawn when a recording has no heightfield: this size [m], centred at the origin.
FLAT_SIZE = (6.0, 3.0)
#: Footstep boxes: the NAO sole (robots/nao.py), 5 mm thick.
SOLE_BOX = (0.160, 0.0888, 0.005)
SOLE_CENTER = (0.030, 0.00562)  # sole centre ahead of / outward of the sole frame [m]
#: Default 3D camera: this offset [m] from the point it looks at (behind-left, above).
EYE_OFFSET = np.array([-0.75, -1.15, 0.55])


# =============================================================================== kinematics



def forward_kinematics(robot: RobotModel, q: np.ndarray, base_pos: np.ndarray, base_quat: np.ndarray
                       ) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    """World poses of all links from joint angles and the floating-base pose.

    Uses the URDF spec of ``robot`` (joint origins ``xyz`` with zero rpy, hinge ``axis``), the same
    kinematics both physics engines import.

    Args:
        robot: the model; its joints must list parents before children.
        q: joint angles [rad], shape (T, 24) in ``robot.joint_names`` order.
        base_pos: root link (torso) origin in the world [m], shape (T, 3).
        base_quat: root orientation, unit quaternions (w, x, y, z), shape (T, 4).

    Returns:
        (links, pos, quat): link names (``robot.links`` order, root first), positions (T, L, 3) [m]
        and orientations (T, L, 4) as quaternions (w, x, y, z).

    Raises:
        ValueError: shapes that do not match.
    """
    q = np.asarray(q, dtype=float)
    base_pos = np.asarray(base_pos, dtype=float)
    base_quat = np.asarray(base_quat, dtype=float)
    n = len(robot.joint_names)
    if q.ndim != 2 or q.shape[1] != n:
        raise ValueError(f"q must have shape (T, {n}), got {q.shape}")
    T = q.shape[0]
    if base_pos.shape != (T, 3) or base_quat.shape != (T, 4):
        raise ValueError(f"base_pos/base_quat must have shapes ({T}, 3)/({T}, 4), got {base_pos.shape}/{base_quat.shape}")
    links = robot.links
    index = {name: i for i, name in enumerate(links)}
    pos = np.empty((T, len(links), 3))
    quat = np.empty((T, len(links), 4))
    pos[:, 0] = base_pos
    quat[:, 0] = base_quat / np.linalg.norm(base_quat, axis=1, keepdims=True)
    for k, j in enumerate(robot.joints):
        ip, ic = index[j.parent], index[j.child]
        qp = quat[:, ip]
        pos[:, ic] = pos[:, ip] + quat_rotate(qp, np.broadcast_to(np.asarray(j.xyz, float), (T, 3)))
        axis = np.asarray(j.axis, float)
        axis = axis / np.linalg.norm(axis)
        half = 0.5 * q[:, k]
        qj = np.concatenate([np.cos(half)[:, None], np.sin(half)[:, None] * axis], axis=1)
        quat[:, ic] = quat_mul(qp, qj)
    return links, pos, quat


def frame_positions(robot: RobotModel, links: tuple[str, ...], pos: np.ndarray, quat: np.ndarray,
                    frame: str, offset=(0.0, 0.0, 0.0)) -> np.ndarray:
    """World position (T, 3) [m] of point ``offset`` [m] given in robot frame ``frame`` (e.g.
    ``l_sole``), from the link poses of :func:`forward_kinematics`."""
    fr = robot.frames[frame]
    i = links.index(fr.link)
    local = np.asarray(fr.offset, float) + np.asarray(offset, float)
    return pos[:, i] + quat_rotate(quat[:, i], np.broadcast_to(local, pos[:, i].shape))



def link_poses(rec: Recording) -> tuple[tuple[str, ...], np.ndarray, np.ndarray, bool]:
    """Per-link world poses of a recording: (links, pos (T, L, 3), quat wxyz (T, L, 4), grounded).

    With ground truth (``gt.base``, ``gt.quat``) the poses are exact (``grounded`` True). A log
    without it (a real robot's) is drawn upright at the origin, tilted by ``angle.roll|pitch`` when
    present, and lifted so that its lower sole touches z = 0 (``grounded`` False).
    """
    robot = rec.robot
    q = rec.group("q")
    T = len(rec)
    if rec.has("gt.base") and rec.has("gt.quat"):
        return (*forward_kinematics(robot, q, rec.group("gt.base"), rec.group("gt.quat")), True)
    if rec.has("angle"):
        ang = rec.group("angle")
        bq = quat_from_rpy(ang[:, 0], ang[:, 1])
    else:
        bq = np.tile([1.0, 0.0, 0.0, 0.0], (T, 1))
    links, pos, quat = forward_kinematics(robot, q, np.zeros((T, 3)), bq)
    low = np.minimum(frame_positions(robot, links, pos, quat, "l_sole")[:, 2],
                     frame_positions(robot, links, pos, quat, "r_sole")[:, 2])
    pos[:, :, 2] -= low[:, None]
    return links, pos, quat, False


def _xyzw(q_wxyz: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(np.concatenate([q_wxyz[..., 1:], q_wxyz[..., :1]], axis=-1))


# =============================================================================== terrain
def terrain_mesh(hf: Heightfield | None, flat_size=FLAT_SIZE) -> dict[str, np.ndarray]:
    """Triangle mesh of a heightfield for ``rr.Mesh3D``.

    Each grid cell is split along its (x0, y0)-(x1, y1) diagonal, MuJoCo's triangulation (the
    surface :meth:`terrain.Heightfield.height_at` evaluates). ``None`` gives a flat quad of
    ``flat_size`` [m] at z = 0.

    Returns:
        dict with ``vertex_positions`` (ny*nx, 3) [m], ``triangle_indices`` (2(ny-1)(nx-1), 3),
        ``vertex_normals`` (ny*nx, 3) and ``vertex_colors`` (ny*nx, 3) uint8 (height-coded).
    """
    if hf is None:
        hx, hy = flat_size[0] / 2, flat_size[1] / 2
        X, Y = np.meshgrid([-hx, hx], [-hy, hy])
        H = np.zeros_like(X)
    else:
        X, Y = np.meshgrid(hf.x, hf.y)
        H = hf.heights
    ny, nx = H.shape
    V = np.stack([X.ravel(), Y.ravel(), H.ravel()], axis=1)
    i00 = (np.arange(ny - 1)[:, None] * nx + np.arange(nx - 1)[None, :]).ravel()
    i10, i01, i11 = i00 + 1, i00 + nx, i00 + nx + 1
    F = np.concatenate([np.stack([i00, i10, i11], 1), np.stack([i00, i11, i01], 1)]).astype(np.uint32)
    if hf is None:
        N = np.tile([0.0, 0.0, 1.0], (len(V), 1))
        C = np.tile(np.array([150, 150, 140], np.uint8), (len(V), 1))
    else:
        gy, gx = np.gradient(H, hf.cell_size)
        N = np.stack([-gx, -gy, np.ones_like(H)], axis=-1).reshape(-1, 3)
        N /= np.linalg.norm(N, axis=1, keepdims=True)
        span = max(hf.max_height - hf.min_height, 1e-9)
        s = ((H - hf.min_height) / span).ravel()[:, None] if hf.max_height > hf.min_height else np.full((len(V), 1), 0.5)
        low, high = np.array([70.0, 110.0, 60.0]), np.array([190.0, 170.0, 120.0])  # turf green -> sand
        C = (low + s * (high - low)).astype(np.uint8)
    return {"vertex_positions": V, "triangle_indices": F, "vertex_normals": N, "vertex_colors": C}


def _terrain_matches(hf: Heightfield, info: dict) -> bool:
    try:
        return (list(hf.shape) == list(info["shape"]) and abs(hf.cell_size - float(info["cell_size"])) < 1e-12
                and abs(hf.min_height - float(info["min"])) < 1e-9 and abs(hf.max_height - float(info["max"])) < 1e-9)
    except (KeyError, TypeError, ValueError):
        return False


def terrain_for(rec: Recording) -> tuple[Heightfield | None, str]:
    """Regenerate the heightfield a recording was made on (heights are not stored in recordings).

    Tried in order, each checked against the recorded ``terrain`` metadata (shape, cell size,
    min/max heights to 1e-9 m):

    1. the real world's per-episode field: ``lumpy(default_rng(SeedSequence(seed).spawn(3)[1]),
       amplitude=effects["terrain_amplitude"])`` (``envs.NaoRealEnv._reset_world``);
    2. ``terrain.make(kind, seed=seed, amplitude=a)`` with kind and amplitude parsed from the
       terrain name (what ``sgatwalk stand --terrain`` builds);
    3. ``terrain.flat`` of the recorded size.

    Returns:
        (heightfield or None for flat ground, a note saying where it came from). When nothing
        matches, None and a note saying that the flat plane drawn is a stand-in.
    """
    from terrain import flat, lumpy, make

    info = rec.meta.get("terrain")
    if not info:
        return None, "flat ground (plane at z = 0)"
    name = str(info.get("name", ""))
    seed = rec.meta.get("seed")
    kind = name.split("(")[0]
    candidates = []
    eff = rec.meta.get("effects") or {}
    if kind == "lumpy" and isinstance(seed, int) and "terrain_amplitude" in eff:
        def real_episode():
            terr_ss = np.random.SeedSequence(seed).spawn(3)[1]
            return lumpy(np.random.default_rng(terr_ss), amplitude=float(eff["terrain_amplitude"]))
        candidates.append(("regenerated from the episode seed (real world's lumpy field)", real_episode))
    m = re.search(r"a=([-+0-9.eE]+)", name) or re.search(r"grade=([-+0-9.eE]+)", name)
    if kind in ("lumpy", "fractal", "steps", "slope") and m and isinstance(seed, int):
        amp = float(m.group(1))
        candidates.append((f"regenerated as terrain.make({kind!r}, seed={seed}, amplitude={amp:g})",
                           lambda: make(kind, seed=seed, amplitude=amp)))
    if kind == "flat":
        def flat_field():
            ny, nx = info["shape"]
            c = float(info["cell_size"])
            return flat(size=((nx - 1) * c, (ny - 1) * c), cell_size=c)
        candidates.append(("flat heightfield", flat_field))
    for note, build in candidates:
        try:
            hf = build()
        except (ValueError, TypeError, KeyError):
            continue
        if _terrain_matches(hf, info):
            return hf, note
    return None, (f"terrain {name!r} could not be regenerated from the metadata; a flat plane at z = 0 stands in "
                  "for it (pass the Heightfield to log_rollouts_to_rrd(terrains=...))")


# =============================================================================== input checks
def check_recording(rec: Recording, label: str = "recording") -> None:
    """Refuse what cannot be shown.

    Raises:
        RecordingError: a recording of another robot, an empty recording, or one that fails
            :meth:`envs.Recording.validate`; the message starts with ``label``.
    """
    if not isinstance(rec, Recording):
        raise RecordingError(f"{label}: expected an envs.Recording, got {type(rec).__name__}")
    if rec.meta.get("robot") != "nao_h25":
        raise RecordingError(f"{label}: recording is of robot {rec.meta.get('robot')!r}; "
                             "the visualizer draws the 'nao_h25' model only")
    if "t" not in rec.columns or len(rec.columns["t"]) == 0:
        raise RecordingError(f"{label}: recording is empty (0 rows)")
    try:
        rec.validate()
    except RecordingError as exc:
        raise RecordingError(f"{label}: {exc}") from None


_PART = re.compile(r"[^A-Za-z0-9_.\-]+")


def sanitize_label(label: str) -> str:
    """An entity-path-safe label: parts separated by '/', each of [A-Za-z0-9_.-] (others -> '_').

    Raises:
        ValueError: an empty label.
    """
    parts = [_PART.sub("_", p).strip("_") or "_" for p in str(label).strip("/").split("/") if p.strip()]
    if not parts:
        raise ValueError(f"empty recording label {label!r}")
    return "/".join(parts)


# =============================================================================== plan from engine
def plan_from_engine(rec: Recording, diagnostics: dict) -> Recording:
    """Add a walk engine's plan to a recording as ``plan.com.*``, ``plan.zmp.*`` and ``footsteps``.

    Args:
        rec: the rollout the engine drove.
        diagnostics: ``walk_engine.WalkEngine.diagnostics()``: arrays ``t`` [s] (the time the
            targets are for), ``com_x|y``, ``zmp_ref_x|y`` in the walk frame [m], and
            ``footsteps`` (phases with ``kind``, ``t0``, ``t1``, ``feet_end``).

    The walk frame is the plan's world: origin between the soles at reset, on the ground, x along
    the initial heading. It is placed in the world at the recording's first row (mid-sole point and
    mean yaw of the two feet, from :func:`link_poses`). Values are interpolated to the recording's times; planned
    CoM height is the engine's ``com_height`` above the ground at the start.

    Returns:
        A new :class:`Recording` (columns and metadata copied, plan added; an existing plan kept).
    """
    if "plan.com.x" in rec.columns or diagnostics is None or len(diagnostics.get("t", ())) == 0:
        return rec
    robot = rec.robot
    links, pos, quat, _ = link_poses(rec)
    mid = 0.5 * (frame_positions(robot, links, pos, quat, "l_sole")[0] + frame_positions(robot, links, pos, quat, "r_sole")[0])
    yaws = []
    for frame in ("l_sole", "r_sole"):  # heading of the feet at the start
        q0 = quat[0, links.index(robot.frames[frame].link)]
        yaws.append(math.atan2(2 * (q0[0] * q0[3] + q0[1] * q0[2]), 1 - 2 * (q0[2] ** 2 + q0[3] ** 2)))
    yaw = math.atan2(sum(math.sin(y) for y in yaws), sum(math.cos(y) for y in yaws))
    c, s = math.cos(yaw), math.sin(yaw)

    def to_world(x, y):
        return mid[0] + c * x - s * y, mid[1] + s * x + c * y

    t = np.asarray(diagnostics["t"], float)
    cols = dict(rec.columns)
    for src, dst in (("com", "plan.com"), ("zmp_ref", "plan.zmp")):
        x = np.interp(rec.t, t, np.asarray(diagnostics[f"{src}_x"], float))
        y = np.interp(rec.t, t, np.asarray(diagnostics[f"{src}_y"], float))
        cols[f"{dst}.x"], cols[f"{dst}.y"] = to_world(x, y)
    com_h = None
    params = rec.meta.get("params")
    if isinstance(params, dict) and "com_height" in params:
        com_h = float(params["com_height"])
    cols["plan.com.z"] = np.full(len(rec), mid[2] + (com_h if com_h is not None else 0.26))
    meta = dict(rec.meta)
    meta.setdefault("footsteps", footsteps_from_phases(diagnostics.get("footsteps", []), to_world, yaw,
                                                       t_end=float(rec.t[-1] + float(rec.meta["control_dt"]))))
    out = Recording(cols, meta)
    out.validate()
    return out


def footsteps_from_phases(phases: list, to_world=lambda x, y: (x, y), yaw0: float = 0.0,
                          t_end: float = math.inf) -> list[dict]:
    """Foot placements from walk-engine phases (``WalkEngine.diagnostics()["footsteps"]``).

    A placement lasts from the end of the swing that put the foot down (or 0 for the initial
    stance) until the start of the next swing of that foot (or ``t_end`` [s]).

    Returns:
        list of ``{"x", "y", "yaw", "side", "t_start", "t_end"}`` (world [m], [rad], [s]).
    """
    out: list[dict] = []
    current: dict[str, dict] = {}
    seen: set[str] = set()

    def place(side, pose, t0):
        x, y, yw = (float(v) for v in pose)
        wx, wy = to_world(x, y)
        current[side] = {"x": float(wx), "y": float(wy), "yaw": yw + yaw0, "side": side, "t_start": t0,
                         "t_end": None}

    for ph in phases:
        feet = ph.get("feet_end") or ph.get("feet") or {}
        t0 = float(ph.get("t0", 0.0))
        t1 = ph.get("t1")
        t1 = math.inf if t1 is None else float(t1)
        if t0 >= t_end:
            break
        swing = {"L": "R", "R": "L"}.get(ph.get("support")) if ph.get("kind") == "ss" else None
        for side in ("L", "R"):
            if side not in seen and side in feet and side != swing:
                seen.add(side)
                place(side, feet[side], 0.0)
        if swing is None or swing not in current:
            continue
        cur = current.pop(swing)
        cur["t_end"] = t0
        out.append(cur)
        if t1 < t_end and swing in feet:
            place(swing, feet[swing], t1)
    for cur in current.values():
        cur["t_end"] = t_end if math.isfinite(t_end) else None
        out.append(cur)
    out = [f for f in out if f["t_end"] is None or f["t_start"] < f["t_end"]]
    out.sort(key=lambda f: (f["t_start"], f["side"]))
    return out


# =============================================================================== logging
def _color(base, mix: float = 0.0) -> list[int]:
    """``base`` RGB blended towards white by ``mix`` in (0, 1], towards black by ``-mix``."""
    b = np.asarray(base, float)
    out = b + mix * (255.0 - b) if mix >= 0 else b * (1.0 + mix)
    return [int(round(v)) for v in out]


def _measured_cop(rec: Recording, robot, links, pos, quat) -> np.ndarray:
    """(T, 3) measured CoP [m] on the ground, NaN when no foot touches (see module docstring)."""
    if rec.has("gt.cop"):
        return rec.group("gt.cop")
    T = len(rec)
    if not (rec.has("fsr") and rec.has("cop")):
        return np.full((T, 3), np.nan)
    f = rec.group("fsr")
    cop = rec.group("cop")
    pl = frame_positions(robot, links, pos, quat, "l_sole")
    pr = frame_positions(robot, links, pos, quat, "r_sole")
    il, ir = links.index(robot.frames["l_sole"].link), links.index(robot.frames["r_sole"].link)
    pl = pl + quat_rotate(quat[:, il], np.column_stack([cop[:, 0], cop[:, 1], np.zeros(T)]))
    pr = pr + quat_rotate(quat[:, ir], np.column_stack([cop[:, 2], cop[:, 3], np.zeros(T)]))
    tot = f[:, 0] + f[:, 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        out = (f[:, :1] * pl + f[:, 1:] * pr) / tot[:, None]
    out[~(tot > 1e-3)] = np.nan
    return out


def _ground_z(hf: Heightfield | None, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    if hf is None:
        return np.zeros_like(np.asarray(x, float))
    hx, hy = hf.half_extent
    return hf.height_at(np.clip(x, -hx, hx), np.clip(y, -hy, hy))


class _Logger:
    """Sends one recording's entities; counts rows per entity for the summary."""

    def __init__(self, stream, label: str, rec: Recording):
        import rerun as rr

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


def log_recording(stream, label: str, rec: Recording, terrain: Heightfield | None = None,
                  terrain_note: str = "", color=None) -> dict[str, int]:
    """Log one recording under ``/<label>`` of an open ``rerun.RecordingStream``.

    Args:
        stream: the Rerun recording stream (e.g. from :func:`log_rollouts_to_rrd`).
        label: entity path of the subtree (already sanitized, without leading '/').
        rec: a checked recording (see :func:`check_recording`).
        terrain: the heightfield it ran on (None: flat plane at z = 0).
        terrain_note: where the terrain came from (shown in the events log).
        color: base RGB colour (default by world).

    Returns:
        {entity path: number of time-varying rows logged}.
    """
    import rerun as rr

    robot = rec.robot
    world = str(rec.meta.get("world", "unknown"))
    color = tuple(color or WORLD_COLORS.get(world, PALETTE[0]))
    L = _Logger(stream, label, rec)
    T = len(rec)

    # ---------------------------------------------------------------- scene
    L.static("", rr.ViewCoordinates.RIGHT_HAND_Z_UP)
    L.static("terrain", rr.Mesh3D(**terrain_mesh(terrain)))

    # ---------------------------------------------------------------- robot
    links, pos, quat, grounded = link_poses(rec)
    xyzw = _xyzw(quat)
    geoms = {robot.root: robot.root_geoms, **{j.child: j.geoms for j in robot.joints}}
    body_col = _color(color, 0.35)
    foot_col = _color(color, 0.0)
    for i, link in enumerate(links):
        L.columns(f"robot/{link}", rr.Transform3D.columns(translation=pos[:, i], quaternion=xyzw[:, i]))
        gs = geoms.get(link, ())
        if not gs:
            continue
        col = foot_col if link.endswith("_ankle") else body_col
        kinds = {g.kind for g in gs}
        if len(kinds) != 1:  # pragma: no cover - the NAO model has one kind per link
            raise ValueError(f"link {link!r} mixes geometry kinds {kinds}")
        kind = kinds.pop()
        qs = [_xyzw(quat_from_rpy(*g.rpy)) for g in gs]
        if kind == "box":
            arch = rr.Boxes3D(centers=[g.xyz for g in gs], half_sizes=[[s / 2 for s in g.size] for g in gs],
                              quaternions=qs, colors=[col] * len(gs), fill_mode="solid")
        elif kind == "capsule":
            # URDF capsule: centred, cylinder of `length` along local z; Rerun: from 0 to +length along z.
            starts = [np.asarray(g.xyz) + quat_rotate(quat_from_rpy(*g.rpy), np.array([0.0, 0.0, -g.size[1] / 2]))
                      for g in gs]
            arch = rr.Capsules3D(lengths=[g.size[1] for g in gs], radii=[g.size[0] for g in gs], translations=starts,
                                 quaternions=qs, colors=[col] * len(gs), fill_mode="solid")
        elif kind == "sphere":
            arch = rr.Ellipsoids3D(centers=[g.xyz for g in gs], half_sizes=[[g.size[0]] * 3 for g in gs],
                                   colors=[col] * len(gs), fill_mode="solid")
        else:  # pragma: no cover - spec error
            raise ValueError(f"unknown geometry kind {kind!r} on link {link!r}")
        L.static(f"robot/{link}/geom", arch)

    # ---------------------------------------------------------------- balance markers
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
                              rec.columns.get("plan.com.z", np.full(T, np.nan))])
        if not np.isfinite(pc[:, 2]).any():
            pc[:, 2] = balance["com"][:, 2] if "com" in balance else 0.26
        balance["plan_com"] = pc
        L.points("plan/com", pc, [250, 200, 0], 0.010)
        L.static("plan/com_trail", rr.LineStrips3D([pc[np.all(np.isfinite(pc), 1)]], colors=[[250, 200, 0]],
                                                   radii=[0.0015]))
    if "plan.zmp.x" in rec.columns:
        zx, zy = rec.columns["plan.zmp.x"], rec.columns["plan.zmp.y"]
        pz = np.column_stack([zx, zy, _ground_z(terrain, zx, zy) + 0.002])
        balance["zmp_ref"] = pz
        L.points("plan/zmp", pz, [0, 200, 200], 0.008)

    # ---------------------------------------------------------------- footsteps
    steps = rec.meta.get("footsteps") or []
    if steps:
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
        sgn = np.array([1.0 if s == "L" else -1.0 for s in side])
        cx = fx + np.cos(fyaw) * SOLE_CENTER[0] - np.sin(fyaw) * sgn * SOLE_CENTER[1]
        cy = fy + np.sin(fyaw) * SOLE_CENTER[0] + np.cos(fyaw) * sgn * SOLE_CENTER[1]
        cz = _ground_z(terrain, cx, cy) + SOLE_BOX[2] / 2
        centers = np.column_stack([cx, cy, cz])
        qs = np.column_stack([np.zeros((len(steps), 2)), np.sin(fyaw / 2), np.cos(fyaw / 2)])
        cols = np.array([[60, 60, 230] if s == "L" else [230, 60, 60] for s in side], np.uint8)
        half = np.tile(np.asarray(SOLE_BOX) / 2, (len(steps), 1))
        labels = [f"{s}{k}" for k, s in enumerate(side)]
        L.static("plan/footsteps", rr.Boxes3D(centers=centers, half_sizes=half, quaternions=qs, colors=cols,
                                              labels=labels, show_labels=False, fill_mode="MajorWireframe"))
        active = (t0[None, :] <= rec.t[:, None]) & (rec.t[:, None] < t1[None, :])  # (T, S)
        rows, idx = np.nonzero(active)
        L.static("plan/footsteps/active", rr.Boxes3D.from_fields(fill_mode="solid"))
        L.columns("plan/footsteps/active", rr.Boxes3D.columns(
            centers=centers[idx], half_sizes=half[idx], quaternions=qs[idx], colors=cols[idx]
        ).partition(active.sum(1).astype(np.int64)))

    # ---------------------------------------------------------------- fall and events
    seed, prof = rec.meta.get("seed"), rec.meta.get("profile")
    tinfo = rec.meta.get("terrain") or {}
    start_msg = (f"{world} rollout: {T} rows x {float(rec.meta['control_dt']) * 1e3:g} ms, seed {seed}"
                 + (f", profile {prof}" if prof else "") + f", terrain {tinfo.get('name', 'flat')}"
                 + (f" ({terrain_note})" if terrain_note else "")
                 + ("" if grounded else "; no ground-truth base pose: robot drawn upright at the origin"))
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

    # ---------------------------------------------------------------- time series
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
    return L.rows


def build_blueprint(labels: list[str], robot: RobotModel, worlds: Mapping[str, str] | None = None,
                    centers: Mapping[str, tuple[float, float, float]] | None = None, active=(0, 0)):
    """The default layout: 3D views side by side on top, compare plots below (one timeline).

    Top: one 3D view per label (origin ``/<label>``), its camera looking at ``centers[label]``
    (world [m], default the origin; e.g. the middle of the torso path) from behind-left; labels
    of the same world (``worlds[label]``) share a column as tabs; a second tab overlays all robots
    on the first label's terrain. ``active``: the initially shown (3D tab, plot tab) indices.
    Bottom tabs: left leg and right leg (one plot per joint: every label's cmd/app/q), IMU (gyro,
    roll, pitch), balance (x and y of CoM, CoP, planned CoM, ZMP reference), feet (FSR) and events.

    Returns:
        ``rerun.blueprint.Blueprint``.
    """
    import rerun.blueprint as rrb

    worlds = dict(worlds or {})
    centers = dict(centers or {})

    def eye(label):
        c = np.asarray(centers.get(label, (0.0, 0.0, 0.2)), float)
        return rrb.EyeControls3D(position=tuple(c + EYE_OFFSET), look_target=tuple(c))

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


def _pick_color(world: str, used: dict[str, int]) -> tuple[int, int, int]:
    """The world's colour for its first recording (sim blue, real orange, grounded green, other
    worlds the next palette entry); later recordings of the same world step through the palette."""
    n = used.get(world, 0)
    used[world] = n + 1
    base = WORLD_COLORS.get(world, PALETTE[(len(used) - 1) % len(PALETTE)])
    return base if n == 0 else PALETTE[(PALETTE.index(base) + 3 * n) % len(PALETTE)]


def log_rollouts_to_rrd(recordings: Mapping[str, Recording], path: str | os.PathLike | None = None, *,
                        terrains: Mapping[str, Heightfield | None] | None = None, spawn: bool = False,
                        application_id: str = "sgatwalk", recording_id: str | None = None,
                        blueprint: bool = True) -> dict:
    """Log recordings side by side into one ``.rrd`` file (or a spawned viewer).

    This is the entry point for ``sgatwalk visualize`` and for ``sgatwalk optimize --rerun``
    (e.g. ``{"gen_005/best": rec, "gen_005/median": rec, "eval/real_seed_3": rec}``).

    Args:
        recordings: label -> recording. A label becomes the entity path ``/<label>`` ('/' nests;
            characters outside [A-Za-z0-9_.-] become '_'); labels must stay distinct and none may be
            a prefix path of another.
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
        ValueError: no recordings, clashing labels, no path; RecordingError (a ValueError) for a
            recording of another robot, an empty or malformed one (message names the label).
    """
    import rerun as rr

    if not recordings:
        raise ValueError("no recordings to visualize")
    if path is None and not spawn:
        raise ValueError("give a path for the .rrd file (or spawn=True)")
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
    terrains = dict(terrains or {})
    robot = next(iter(labels.values())).robot
    t_start = time.perf_counter()
    stream = rr.RecordingStream(application_id, recording_id=recording_id)
    if not stream.is_enabled():
        raise ValueError("Rerun logging is disabled (environment variable RERUN=off?); unset it to write .rrd files")
    bp = None
    if blueprint:
        centers = {}
        for k, r in labels.items():
            if r.has("gt.base"):
                b = r.group("gt.base")
                centers[k] = (0.5 * (b[:, 0].min() + b[:, 0].max()), 0.5 * (b[:, 1].min() + b[:, 1].max()), 0.2)
        bp = build_blueprint(list(labels), robot, {k: str(r.meta.get("world", k)) for k, r in labels.items()}, centers)
    rows: dict[str, int] = {}
    notes: dict[str, str] = {}
    used: dict[str, int] = {}
    t_log = 0.0
    if spawn:
        import shutil
        import sys

        venv_bin = os.path.dirname(sys.executable)  # the viewer ships with rerun-sdk, next to python
        if shutil.which("rerun") is None and os.path.exists(os.path.join(venv_bin, "rerun")):
            os.environ["PATH"] = venv_bin + os.pathsep + os.environ.get("PATH", "")
    else:
        path = os.fspath(path)
    # a file is written to a temporary beside it and renamed when complete (common.files.atomic_path)
    with contextlib.nullcontext(None) if spawn else atomic_path(path, suffix=".rrd") as tmp:
        if spawn:
            stream.spawn(default_blueprint=bp)
        else:
            stream.save(tmp, default_blueprint=bp)
        try:
            stream.log("/legend", rr.TextDocument(LEGEND_MD, media_type=rr.MediaType.MARKDOWN), static=True)
            for lab, rec in labels.items():
                if lab in terrains or orig[lab] in terrains:
                    hf = terrains.get(lab, terrains.get(orig[lab]))
                    note = "flat ground (plane at z = 0)" if hf is None else "the rollout's terrain"
                else:
                    hf, note = terrain_for(rec)
                notes[lab] = note
                rows.update(log_recording(stream, lab, rec, hf, note, _pick_color(str(rec.meta.get("world", "")), used)))
            t_log = time.perf_counter() - t_start
            stream.flush()
        finally:
            stream.disconnect()
    size = 0 if spawn else os.path.getsize(path)
    return {"path": None if spawn else path, "labels": list(labels), "rows": rows, "notes": notes,
            "log_seconds": t_log, "seconds": time.perf_counter() - t_start, "bytes": size}


# =============================================================================== inputs
def _is_recording_file(path: str) -> bool:
    """Whether a Parquet file carries ``sgatwalk`` recording metadata (cheap: schema only)."""
    import pyarrow.parquet as pq

    from envs.recording import META_KEY

    try:
        md = pq.read_schema(path).metadata or {}
    except Exception:  # noqa: BLE001 - not Parquet at all: let from_parquet name the problem
        return True
    return META_KEY in md


def find_recordings(paths: list[str]) -> tuple[dict[str, Recording], list[str]]:
    """Load recordings from Parquet files and directories and label them by world.

    A directory (e.g. an ``optimize`` run directory) contributes every ``*.parquet`` below it,
    recursively, that carries recording metadata; other Parquet files there (``evals.parquet``)
    are skipped. Labels: the metadata ``world`` when a world has one recording, else
    ``<world>/<relative path without .parquet>`` for each of them. Order: sim, real, grounded,
    then other worlds alphabetically; within a world by path.

    Returns:
        (label -> recording, skipped paths).

    Raises:
        FileNotFoundError: a path that does not exist; a directory without recordings.
        RecordingError: a file given explicitly that is not a valid recording, a malformed
            recording in a directory, a recording of another robot, an empty recording
            (the message names the file).
    """
    found: list[tuple[str, str]] = []  # (file, name used for the label)
    skipped: list[str] = []
    for p in paths:
        p = os.fspath(p)
        if os.path.isdir(p):
            files = []
            for dirpath, dirnames, filenames in os.walk(p):
                dirnames.sort()
                files += [os.path.join(dirpath, f) for f in sorted(filenames) if f.endswith(".parquet")]
            recs = [f for f in files if _is_recording_file(f)]
            skipped += [f for f in files if f not in recs]
            if not recs:
                raise FileNotFoundError(f"no recordings (*.parquet with sgatwalk metadata) under {p!r}")
            found += [(f, os.path.relpath(f, p)[: -len(".parquet")]) for f in recs]
        elif os.path.exists(p):
            found.append((p, os.path.splitext(os.path.basename(p))[0]))
        else:
            raise FileNotFoundError(f"no recording at {p!r}")
    loaded: list[tuple[str, str, Recording]] = []
    for f, name in found:
        try:
            rec = Recording.from_parquet(f)
        except RecordingError as exc:
            msg = str(exc)
            raise RecordingError(msg if f in msg else f"{f}: {msg}") from None
        check_recording(rec, f)
        loaded.append((f, name, rec))
    rank = {w: i for i, w in enumerate(WORLD_COLORS)}  # sim, real, grounded first: left to right
    loaded.sort(key=lambda x: (rank.get(str(x[2].meta.get("world")), len(rank)), str(x[2].meta.get("world")), x[1]))
    count: dict[str, int] = {}
    for _, _, rec in loaded:
        w = str(rec.meta.get("world", "recording"))
        count[w] = count.get(w, 0) + 1
    out: dict[str, Recording] = {}
    for f, name, rec in loaded:
        w = sanitize_label(str(rec.meta.get("world", "recording")))
        lab = w if count[str(rec.meta.get("world", "recording"))] == 1 else f"{w}/{sanitize_label(name)}"
        base, k = lab, 2
        while lab in out:
            lab = f"{base}_{k}"
            k += 1
        out[lab] = rec
    return out, skipped


# =============================================================================== screenshot
def screenshot_rrd(rrd_path: str | os.PathLike, png_path: str | os.PathLike, *, time_s: float | None = None,
                   settle_s: float = 3.0) -> str:
    """Render an ``.rrd`` with its default blueprint in a headless Rerun viewer and save a PNG.

    Spawns ``rerun --headless`` (the viewer binary of the installed rerun-sdk) on a free port,
    opens the file, moves the time cursor to ``time_s`` [s] on the ``time`` timeline, waits
    ``settle_s`` [s] for the views to load and saves a 1920 x 1080 screenshot
    (``rerun.experimental.ViewerClient``, rerun-sdk 0.41). About 10 s on a CPU.

    Needs a graphics adapter: a GPU, or on Linux without one Mesa's lavapipe Vulkan driver
    (Debian/Ubuntu package ``mesa-vulkan-drivers``); ``WGPU_BACKEND`` defaults to ``vulkan`` on
    Linux.

    Returns:
        the PNG path.

    Raises:
        FileNotFoundError: no such ``.rrd``.
        RuntimeError: no ``rerun`` executable, no graphics adapter, or the viewer failed.
    """
    import shutil
    import socket
    import sys

    rrd_path = os.path.abspath(os.fspath(rrd_path))
    png_path = os.path.abspath(os.fspath(png_path))
    if not os.path.exists(rrd_path):
        raise FileNotFoundError(f"no Rerun file at {rrd_path!r}")
    exe = shutil.which("rerun") or os.path.join(os.path.dirname(sys.executable), "rerun")
    if not os.path.exists(exe):
        raise RuntimeError("no 'rerun' viewer executable found (it comes with rerun-sdk; put its bin/ on PATH)")
    try:
        from rerun.experimental import ViewerClient
    except ImportError as exc:  # pragma: no cover - rerun-sdk < 0.41
        raise RuntimeError(f"this rerun-sdk has no headless viewer client: {exc}") from None
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env_keys = {}
    if sys.platform.startswith("linux"):
        env_keys = {"WGPU_BACKEND": "vulkan", "XDG_RUNTIME_DIR": tempfile_dir()}
    saved = {k: os.environ.get(k) for k in env_keys}
    for k, v in env_keys.items():
        os.environ.setdefault(k, v)
    viewer = None
    try:
        os.makedirs(os.path.dirname(png_path), exist_ok=True)
        if os.path.exists(png_path):
            os.remove(png_path)
        with _quiet_child_output():
            viewer = ViewerClient.spawn(headless=True, port=port, hide_welcome_screen=True, executable_path=exe)
        viewer.open(rrd_path)
        time.sleep(settle_s / 2)
        if time_s is not None:
            viewer.set_time(TIMELINE, duration=float(time_s), play_state="paused")
        time.sleep(settle_s / 2)
        viewer.save_screenshot(png_path)
    except Exception as exc:  # noqa: BLE001 - the viewer reports many kinds of failure
        raise RuntimeError(f"headless Rerun viewer failed ({type(exc).__name__}: {str(exc)[:300]}); a GPU or "
                           "Mesa's lavapipe Vulkan driver (mesa-vulkan-drivers) is needed") from None
    finally:
        if viewer is not None:
            try:
                viewer.quit()
            except Exception:  # noqa: BLE001 - best effort
                pass
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    if not os.path.exists(png_path):
        raise RuntimeError("the headless Rerun viewer saved no screenshot")
    return png_path


class _quiet_child_output:
    """Point fds 1 and 2 at /dev/null while a child process is spawned (it inherits them), so the
    headless viewer's log lines do not mix with the command's output."""

    def __enter__(self):
        import sys

        for f in (sys.stdout, sys.stderr):
            try:
                f.flush()
            except Exception:  # noqa: BLE001 - best effort
                pass
        self.saved = [os.dup(1), os.dup(2)]
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, 1)
        os.dup2(null, 2)
        os.close(null)
        return self

    def __exit__(self, *exc):
        os.dup2(self.saved[0], 1)
        os.dup2(self.saved[1], 2)
        for fd in self.saved:
            os.close(fd)
        return False


def tempfile_dir() -> str:
    """A private runtime directory for the headless viewer (``XDG_RUNTIME_DIR`` must be 0700)."""
    import tempfile

    d = os.path.join(tempfile.gettempdir(), f"sgatwalk-xdg-{os.getuid()}")
    os.makedirs(d, mode=0o700, exist_ok=True)
    return d
