"""Kajita preview control on fixed footstep plans, and the footstep planner."""

import math

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from walk_engine import GaitParams, WalkCommand, WalkEngine, ZmpPreview, plan_phases, preview_gains
from walk_engine.footsteps import STEP_LIMITS, FootstepPlanner, SupportPolygon, zmp_reference
from walk_engine.preview import lipm_period_sway

DT = 0.01
SOLE = SupportPolygon()


def _support_polygon(phase, t):
    """Convex support polygon (as ConvexHull) of the planned feet at time t."""
    if phase.kind == "ss":
        pts = SOLE.foot_corners(phase.support, phase.feet[phase.support])
    else:
        pts = np.vstack([SOLE.foot_corners(s, phase.feet_end[s]) for s in "LR"])
    return ConvexHull(pts)


def _inside(hull, p, tol=1e-9):
    return bool(np.all(hull.equations[:, :2] @ p + hull.equations[:, 2] <= tol))


def _sample_reference(phases, n):
    t = np.arange(n) * DT
    ref = np.empty((n, 2))
    owner = np.empty(n, dtype=int)
    for i, ph in enumerate(phases):
        m = (t >= ph.t0 - 1e-9) & (t < ph.t1 - 1e-9)
        ref[m] = zmp_reference(ph, t[m])
        owner[m] = i
    return t, ref, owner


def test_gains_stabilise_and_preview_decays():
    Gi, Gx, Gp = preview_gains(0.265, 1e-6, DT, 100)
    pv = ZmpPreview(0.265, -6.0)
    At = np.zeros((4, 4))
    At[0, 0] = 1
    At[0, 1:] = pv.C @ pv.A
    At[1:, 1:] = pv.A
    Bt = np.concatenate([[pv.C @ pv.B], pv.B])
    K = np.concatenate([[Gi], Gx])
    assert np.abs(np.linalg.eigvals(At - np.outer(Bt, K))).max() < 1.0
    assert abs(Gp[-1]) < 1e-2 * abs(Gp[0])  # a 1 s horizon is ample (LIPM time constant √(z_c/g) ≈ 0.16 s)


@pytest.mark.parametrize("period", [0.25, 0.3, 0.4])
def test_lateral_sway_matches_lipm_theory(period):
    """Bang-bang ZMP ±5 cm: the planned CoM's steady sway equals the LIPM periodic orbit."""
    z_c = 0.265
    t = np.arange(0, 8, DT)
    y = np.where(t < 1, 0.0, np.where(np.floor((t - 1) / period) % 2 == 0, 0.05, -0.05))
    X, _ = ZmpPreview(z_c, -8.0).plan(np.stack([np.zeros_like(t), y], 1))
    sway = np.ptp(X[300:600, 0, 1])
    assert sway == pytest.approx(2 * lipm_period_sway(z_c, period, 0.05), rel=0.05)


@pytest.mark.parametrize("kw", [{}, {"step_period": 0.4, "step_length": 0.06},
                                {"double_support_ratio": 0.35, "feet_spacing": 0.12}])
def test_planned_zmp_tracks_reference_inside_support_polygon(kw):
    """Fixed plan: walk 5 s, stop, stand. The cart-table ZMP of the planned CoM stays in the
    support polygon and tracks the reference within 5 mm RMS."""
    params = GaitParams(**kw)
    phases = plan_phases(params, seconds=9.0, stop_after=5.0)
    assert phases[-1].kind == "stand" and not math.isfinite(phases[-1].t1)
    n = 900
    t, ref, owner = _sample_reference(phases, n)
    X, zmp = ZmpPreview(params.com_height, params.preview_log10_R).plan(ref)
    err = zmp - ref
    rms = float(np.sqrt(np.mean(np.sum(err**2, axis=1))))
    assert rms < 0.005, rms
    for k in range(n):
        ph = phases[owner[k]]
        assert _inside(_support_polygon(ph, t[k]), zmp[k]), (k, ph.kind, zmp[k])
    # the CoM comes to rest between the feet at the end
    assert np.abs(X[-1, 1:]).max() < 1e-3


def test_engine_plan_equals_offline_plan():
    """The engine's incremental preview gives the same CoM and ZMP as the offline plan."""
    params = GaitParams()
    eng = WalkEngine(params=params)
    obs = np.zeros(62)
    for _ in range(600):
        eng.step(obs)
    d = eng.diagnostics()
    phases = plan_phases(params, seconds=9.0)
    _, ref, _ = _sample_reference(phases, 800)  # the offline plan must see the same future
    X, zmp = ZmpPreview(params.com_height, params.preview_log10_R).plan(ref)
    X, zmp, ref = X[:601], zmp[:601], ref[:601]
    # diagnostics row k is the state at tick k + 1
    np.testing.assert_allclose(d["com_x"], X[1:, 0, 0], atol=1e-12)
    np.testing.assert_allclose(d["com_y"], X[1:, 0, 1], atol=1e-12)
    np.testing.assert_allclose(d["zmp_ref_x"], ref[1:, 0], atol=1e-12)
    np.testing.assert_allclose(d["zmp_y"], zmp[1:, 1], atol=1e-12)


# ------------------------------------------------------------------------------ footsteps
def _polygon_gap(A, B):
    """Distance between two disjoint convex polygons (corners (4, 2)); 0 if they overlap."""
    for P, Q in ((A, B), (B, A)):
        if any(_inside(ConvexHull(Q), p) for p in P):
            return 0.0

    def seg_dist(p, a, b):
        t = np.clip(np.dot(p - a, b - a) / np.dot(b - a, b - a), 0, 1)
        return np.linalg.norm(p - (a + t * (b - a)))

    return min(seg_dist(p, Q[i], Q[(i + 1) % 4]) for P, Q in ((A, B), (B, A)) for p in P for i in range(4))


def _steps(params, command, n):
    pl = FootstepPlanner(params, command)
    out = []
    while len(out) < n:
        ph = pl.next_phase()
        if ph.kind == "ss":
            out.append(ph)
    return out


def test_forward_steps_ramp_to_step_length():
    p = GaitParams(step_length=0.05)
    ss = _steps(p, WalkCommand(), 12)
    adv = [ph.feet_end[ph.swing][0] - ph.feet[ph.swing][0] for ph in ss]
    # first steps ramp up (start step), later steps move the foot 2 step lengths
    assert adv[0] < adv[2] < adv[-1]
    assert adv[-1] == pytest.approx(2 * 0.05)
    for ph in ss:
        assert ph.t1 - ph.t0 == pytest.approx(p.step_period * (1 - p.double_support_ratio))


def test_command_is_clipped_to_limits():
    p = GaitParams()
    pl = FootstepPlanner(p, WalkCommand(vx=10.0, vy=10.0, wz=10.0))
    d = pl.target_step()
    semi = np.array([p.step_length, STEP_LIMITS["dy"], STEP_LIMITS["dtheta"]])
    assert np.sum((d / semi) ** 2) == pytest.approx(1.0)
    pl = FootstepPlanner(p, WalkCommand(vx=-10.0))
    assert pl.target_step()[0] == pytest.approx(-STEP_LIMITS["dx_back"])


@pytest.mark.parametrize("cmd", [WalkCommand(0.0, 0.08, 0.0), WalkCommand(0.0, -0.08, 0.0),
                                 WalkCommand(0.05, 0.0, 0.6), WalkCommand(0.0, 0.0, -0.6)])
def test_sideways_and_turning_never_narrow_or_toe_in(cmd):
    p = GaitParams()
    for ph in _steps(p, cmd, 20):
        L, R = ph.feet_end["L"], ph.feet_end["R"]
        yaw = R[2] + (L[2] - R[2]) / 2
        lateral = -math.sin(yaw) * (L[0] - R[0]) + math.cos(yaw) * (L[1] - R[1])
        assert lateral > 0.9 * p.feet_spacing  # the left foot stays left of the right one
        # relative yaw of the feet: toes out only (left foot yawed left of the right foot or equal)
        assert (L[2] - R[2] + math.pi) % (2 * math.pi) - math.pi >= -1e-9
        # the soles never touch: at least 5 mm between the two rectangles
        assert _polygon_gap(SOLE.foot_corners("L", L), SOLE.foot_corners("R", R)) > 0.005
    first = _steps(p, cmd, 1)[0]
    assert first.swing == ("L" if (cmd.vy > 0 or (cmd.vy == 0 and cmd.wz > 0)) else "R")


def test_stop_brings_feet_together_and_stands():
    p = GaitParams()
    phases = plan_phases(p, seconds=30.0, stop_after=3.0)
    kinds = [ph.kind for ph in phases]
    assert kinds[:2] == ["stand", "start"] and kinds[-2:] == ["stop", "stand"]
    last = phases[-1]
    L, R = last.feet["L"], last.feet["R"]
    assert L[0] == pytest.approx(R[0]) and L[2] == pytest.approx(R[2])
    assert math.hypot(L[0] - R[0], L[1] - R[1]) == pytest.approx(p.feet_spacing)
    mid = ((L[0] + R[0]) / 2 + p.zmp_offset_x, (L[1] + R[1]) / 2)
    assert last.zmp0 == pytest.approx(mid)
