"""Velocity command -> footsteps -> support phases with their ZMP reference.

Stage 1 and 2 of :mod:`walk_engine.engine` (structure after Rhoban placo's
``FootstepsPlanner`` / ``make_supports``, github.com/Rhoban/placo, ``src/placo/humanoid``):

* A *centre* frame (x, y, yaw) between the feet moves by (dx, dy, dθ) per step in its own frame;
  the swing foot lands at the new centre ± ``feet_spacing``/2. Sideways and turning motion is done
  only by the foot on the side of the motion (it moves by 2 dy / 2 dθ while the other foot just
  catches up), so the feet never come closer than ``feet_spacing`` and never toe in.
* The per-step displacement (dx, dy, dθ) = (vx, vy, ωz) · step_period is clipped to an ellipsoid
  with semi-axes :data:`STEP_LIMITS` (forward limit = the gait's ``step_length``) and may change by
  at most :data:`STEP_CHANGE` per step (start: ramp up from rest; stop: ramp down, then one step
  that brings the feet side by side).
* Phases: ``stand`` (ZMP between the feet), ``start`` (ZMP moves to the first support foot over
  max(2 T_ds, :data:`MIN_TRANSFER`)), then per step ``ss`` (single support, swing foot moving) and
  ``ds`` (ZMP moves linearly to the next support foot); after a stop a ``stop`` transfer back to the
  middle and ``stand`` forever.
* The ZMP reference of a support foot is its ankle projection + (zmp_offset_x, ± zmp_offset_y
  outward) rotated by the foot's yaw.

World frame of the plan ("walk frame"): origin midway between the feet at reset, x forward,
z = 0 on the ground. Poses are (x [m], y [m], yaw [rad]).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from common.defaults import EPISODE_SECONDS
from walk_engine.params import GaitParams

#: Semi-axes of the per-step displacement ellipsoid: backward dx [m], sideways dy [m] (average per
#: step; the moving foot travels twice that), turn dθ [rad] (average per step). The forward semi-axis
#: is the gait's ``step_length``. Lengths are the NAO's; other robots scale them by their
#: ``GaitParams.length_scale`` (here and in :data:`STEP_CHANGE`).
STEP_LIMITS = {"dx_back": 0.03, "dy": 0.025, "dtheta": 0.15}
#: Largest change of (dx [m], dy [m], dθ [rad]) from one step to the next (start/stop ramps).
STEP_CHANGE = (0.02, 0.01, 0.10)
#: Shortest start/stop ZMP transfer [s].
MIN_TRANSFER = 0.15
#: Time [s] the robot stands (ZMP between the feet) after reset before the start transfer.
STAND_TIME = 0.25


@dataclass(frozen=True)
class WalkCommand:
    """Walking velocity command in the robot's heading frame.

    Args:
        vx: forward speed [m/s]; None = the gait's own speed ``step_length / step_period``.
        vy: sideways speed [m/s], + left.
        wz: turn rate [rad/s], + counter-clockwise (left).

    Raises:
        ValueError: a non-finite component.
    """

    vx: float | None = None
    vy: float = 0.0
    wz: float = 0.0

    def __post_init__(self):
        for k in ("vx", "vy", "wz"):
            v = getattr(self, k)
            if v is None and k == "vx":
                continue
            if not (isinstance(v, (int, float)) and math.isfinite(v)):
                raise ValueError(f"walk command {k} must be a finite number, got {v!r}")


STAND = WalkCommand(0.0, 0.0, 0.0)


@dataclass
class Phase:
    """One support phase of the plan.

    Attributes:
        kind: ``"stand"``, ``"start"``, ``"ss"``, ``"ds"``, ``"stop"``.
        t0, t1: start and end time [s] (``t1 = inf`` for the final stand).
        support: ``"L"``/``"R"`` stance foot in ``ss``; the foot receiving the weight at the end
            of a transfer (``start``/``ds``); ``""`` for ``stand``/``stop`` (both feet).
        feet: {"L": (x, y, yaw), "R": ...} foot poses at the start of the phase.
        feet_end: foot poses at the end (differ from ``feet`` for the swing foot of ``ss``).
        zmp0, zmp1: ZMP reference (x, y) [m] at t0 and t1 (linear in between).
        step_index: number of the step (``ss``) or -1.
    """

    kind: str
    t0: float
    t1: float
    support: str
    feet: dict
    feet_end: dict
    zmp0: tuple
    zmp1: tuple
    step_index: int = -1

    @property
    def swing(self) -> str:
        """The swing foot of an ``ss`` phase ('' otherwise)."""
        return ("R" if self.support == "L" else "L") if self.kind == "ss" else ""

    def weight_line(self) -> tuple[float, float]:
        """The left-foot weight share as ``c0 + c1 * s``, s the phase fraction in [0, 1]
        (:meth:`weight_left`; constant in ``ss`` and ``stand``, c1 = 0)."""
        w = 1.0 if self.support == "L" else 0.0
        if self.kind == "ss":
            return w, 0.0
        if self.kind == "stand":
            return 0.5, 0.0
        if self.kind == "start":  # support = the foot that gets the weight
            return 0.5, w - 0.5
        if self.kind == "stop":  # support = the foot that had the weight
            return w, 0.5 - w
        return 1.0 - w, 2.0 * w - 1.0  # ds: the weight moves to `support`

    def weight_left(self, t: float) -> float:
        """Planned share of the weight on the left foot at time t (0..1), from the ZMP schedule."""
        c0, c1 = self.weight_line()
        return c0 + c1 * _frac(self, t)


def _frac(ph: Phase, t: float) -> float:
    if not math.isfinite(ph.t1) or ph.t1 <= ph.t0:
        return 1.0
    return min(1.0, max(0.0, (t - ph.t0) / (ph.t1 - ph.t0)))


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


class FootstepPlanner:
    """Lazily generates the :class:`Phase` sequence of a walk (see module docstring).

    Args:
        params: the gait parameters (step period, double-support ratio, step length, feet
            spacing, ZMP offsets are used).
        command: the initial :class:`WalkCommand`.

    Deterministic: the same params and command sequence give the same phases.
    """

    def __init__(self, params: GaitParams, command: WalkCommand | None = None):
        self.p = params
        self.T = params.step_period
        self.T_ds = params.double_support_ratio * params.step_period
        self.T_ss = self.T - self.T_ds
        self.T_transfer = max(2.0 * self.T_ds, MIN_TRANSFER)
        h = params.feet_spacing / 2.0
        self.feet = {"L": (0.0, h, 0.0), "R": (0.0, -h, 0.0)}
        self.centre = (0.0, 0.0, 0.0)
        self.step = np.zeros(3)  # current per-step displacement (dx, dy, dθ)
        self.command = command or WalkCommand()
        self.stop_requested = False
        self._t = 0.0
        self._state = "stand0"
        self._next_swing = "R"
        self._support = "L"
        self._n_steps = 0
        self._aligned = False

    # ------------------------------------------------------------------ commands
    def set_command(self, command: WalkCommand) -> None:
        """Change the velocity command; takes effect at the next planned step (ramped)."""
        self.command = command
        self.stop_requested = False

    def request_stop(self) -> None:
        """Ramp down to zero, bring the feet side by side and stand."""
        self.stop_requested = True

    def target_step(self) -> np.ndarray:
        """The per-step displacement (dx, dy, dθ) the command asks for, clipped to the ellipsoid."""
        if self.stop_requested:
            return np.zeros(3)
        c = self.command
        vx = self.p.step_length / self.T if c.vx is None else c.vx
        d = np.array([vx * self.T, c.vy * self.T, c.wz * self.T])
        k = type(self.p).length_scale  # 1 for the NAO; other robots' leg length / the NAO's
        ax = self.p.step_length if d[0] >= 0 else STEP_LIMITS["dx_back"] * k
        semi = np.array([max(ax, 1e-9), STEP_LIMITS["dy"] * k, STEP_LIMITS["dtheta"]])
        r = math.sqrt(float(np.sum((d / semi) ** 2)))
        return d / r if r > 1.0 else d

    # ------------------------------------------------------------------ geometry
    def zmp_of(self, side: str, pose=None) -> tuple[float, float]:
        """ZMP reference (x, y) [m] under foot ``side`` (its pose, or the current one)."""
        x, y, yaw = pose if pose is not None else self.feet[side]
        ox = self.p.zmp_offset_x
        oy = self.p.zmp_offset_y * (1.0 if side == "L" else -1.0)
        c, s = math.cos(yaw), math.sin(yaw)
        return (x + c * ox - s * oy, y + s * ox + c * oy)

    def _middle(self) -> tuple[float, float]:
        a, b = self.zmp_of("L"), self.zmp_of("R")  # the outward offsets cancel
        return ((a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0)

    def _phase(self, kind, dur, support, zmp0, zmp1, feet_end=None, idx=-1) -> Phase:
        ph = Phase(kind, self._t, self._t + dur, support, dict(self.feet), dict(feet_end or self.feet),
                   tuple(zmp0), tuple(zmp1), idx)
        self._t = ph.t1
        if feet_end:
            self.feet = dict(feet_end)
        return ph

    def _plan_step(self, swing: str) -> dict:
        """Advance the centre for a step of ``swing`` and return the new foot poses."""
        want = self.target_step()
        k = type(self.p).length_scale
        ch = np.array([STEP_CHANGE[0] * k, STEP_CHANGE[1] * k, STEP_CHANGE[2]])
        self.step = self.step + np.clip(want - self.step, -ch, ch)
        dx, dy, dth = (float(v) for v in self.step)
        sgn = 1.0 if swing == "L" else -1.0
        # sideways / turning: only the foot on the side of the motion leads (twice the average)
        lead_y = 2.0 * dy if (dy * sgn) > 0 else 0.0
        lead_th = 2.0 * dth if (dth * sgn) > 0 else 0.0
        cx, cy, cth = self.centre
        c, s = math.cos(cth), math.sin(cth)
        cx, cy = cx + c * dx - s * lead_y, cy + s * dx + c * lead_y
        cth = _wrap(cth + lead_th)
        self.centre = (cx, cy, cth)
        h = self.p.feet_spacing / 2.0 * sgn
        c, s = math.cos(cth), math.sin(cth)
        feet = dict(self.feet)
        feet[swing] = (cx - s * h, cy + c * h, cth)
        return feet

    def _feet_aligned(self) -> bool:
        """Both feet side by side at the centre (after a stop)."""
        cx, cy, cth = self.centre
        h = self.p.feet_spacing / 2.0
        c, s = math.cos(cth), math.sin(cth)
        want = {"L": (cx - s * h, cy + c * h), "R": (cx + s * h, cy - c * h)}
        return all(math.hypot(self.feet[k][0] - want[k][0], self.feet[k][1] - want[k][1]) < 1e-9
                   and abs(_wrap(self.feet[k][2] - cth)) < 1e-9 for k in "LR")

    # ------------------------------------------------------------------ phase generation
    def next_phase(self) -> Phase:
        """The next phase of the plan (infinite sequence; ends in an endless ``stand`` after a stop)."""
        st = self._state
        if st == "stand0":
            self._state = "start"
            m = self._middle()
            return self._phase("stand", STAND_TIME, "", m, m)
        if st == "start":
            # first swing foot: the one on the side of the sideways/turn motion, else the right foot
            want = self.target_step()
            first = "L" if (want[1] > 1e-9 or (abs(want[1]) <= 1e-9 and want[2] > 1e-9)) else "R"
            self._support = "R" if first == "L" else "L"
            self._state = "ss"
            return self._phase("start", self.T_transfer, self._support, self._middle(), self.zmp_of(self._support))
        if st == "ss":
            sup = self._support
            swing = "R" if sup == "L" else "L"
            stopping = self.stop_requested and not np.any(np.abs(self.step) > 1e-12)
            if stopping:
                feet = dict(self.feet)
                cx, cy, cth = self.centre
                h = self.p.feet_spacing / 2.0 * (1.0 if swing == "L" else -1.0)
                feet[swing] = (cx - math.sin(cth) * h, cy + math.cos(cth) * h, cth)
            else:
                feet = self._plan_step(swing)
            self._n_steps += 1
            z = self.zmp_of(sup)
            ph = self._phase("ss", self.T_ss, sup, z, z, feet, idx=self._n_steps - 1)
            if stopping and self._feet_aligned():
                self._state = "stop"
            else:
                self._state = "ds"
            return ph
        if st == "ds":
            sup = self._support
            new = "R" if sup == "L" else "L"
            self._support = new
            self._state = "ss"
            return self._phase("ds", self.T_ds, new, self.zmp_of(sup), self.zmp_of(new))
        if st == "stop":
            self._state = "end"
            return self._phase("stop", self.T_transfer, self._support, self.zmp_of(self._support), self._middle())
        m = self._middle()
        return self._phase("stand", math.inf, "", m, m)


def zmp_reference(phase: Phase, t: np.ndarray) -> np.ndarray:
    """ZMP reference [m] of ``phase`` at times ``t`` [s], shape (len(t), 2) (linear in time)."""
    t = np.asarray(t, dtype=float)
    if not math.isfinite(phase.t1) or phase.t1 <= phase.t0:
        s = np.zeros_like(t)
    else:
        s = np.clip((t - phase.t0) / (phase.t1 - phase.t0), 0.0, 1.0)
    z0, z1 = np.asarray(phase.zmp0), np.asarray(phase.zmp1)
    return z0[None, :] + s[:, None] * (z1 - z0)[None, :]


def plan_phases(params: GaitParams, command: WalkCommand | None = None, seconds: float = EPISODE_SECONDS,
                stop_after: float | None = None) -> list[Phase]:
    """All phases that start before ``seconds`` [s]; with ``stop_after`` [s], a stop is requested
    at the first step starting after that time (a fixed plan for tests and plots)."""
    pl = FootstepPlanner(params, command)
    out = []
    while True:
        if stop_after is not None and pl._t >= stop_after:
            pl.request_stop()
        ph = pl.next_phase()
        out.append(ph)
        if ph.t1 >= seconds or not math.isfinite(ph.t1):
            return out


@dataclass
class SupportPolygon:
    """Sole rectangle of the robot's foot in the foot frame: x from ``back`` to ``front`` [m] of the
    ankle projection, y from ``-inner``..``outer`` (left foot; mirrored). The defaults are the NAO's
    (``robots.nao.NAO_SOLE``)."""

    front: float = 0.110
    back: float = -0.050
    inner: float = 0.03878
    outer: float = 0.05002

    @classmethod
    def for_robot(cls, robot) -> "SupportPolygon":
        """The sole rectangle of ``robot`` (a ``robots.RobotModel``): its ``sole`` where the model gives
        one, else the left foot's collision box seen from the ``l_sole`` frame.

        Raises:
            ValueError: the left foot has no collision box.
        """
        if robot.sole is not None:
            return cls(*robot.sole)
        sole = robot.frames["l_sole"]
        foot = next(j for j in robot.joints if j.child == sole.link)
        boxes = [g for g in foot.geoms if g.kind == "box" and g.collide]
        if not boxes:
            raise ValueError(f"{robot.name}: the left foot {sole.link} has no collision box")
        g = boxes[0]
        cx, cy = g.xyz[0] - sole.offset[0], g.xyz[1] - sole.offset[1]
        return cls(front=cx + g.size[0] / 2, back=cx - g.size[0] / 2, inner=-(cy - g.size[1] / 2),
                   outer=cy + g.size[1] / 2)

    def foot_corners(self, side: str, pose) -> np.ndarray:
        """Corners (4, 2) [m] of the sole of foot ``side`` at ``pose`` (x, y, yaw)."""
        s = 1.0 if side == "L" else -1.0
        pts = np.array([[self.front, s * self.outer], [self.front, -s * self.inner],
                        [self.back, -s * self.inner], [self.back, s * self.outer]])
        x, y, yaw = pose
        c, sn = math.cos(yaw), math.sin(yaw)
        R = np.array([[c, -sn], [sn, c]])
        return pts @ R.T + np.array([x, y])
