"""A walk engine's plan as recording columns: planned CoM, ZMP reference and footsteps."""

from __future__ import annotations

import math

import numpy as np

from envs.recording import Recording
from experiments.viz.kinematics import frame_positions, link_poses


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
