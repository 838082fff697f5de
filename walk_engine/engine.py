"""The ZMP walk engine: (time, observation) -> 23 joint targets at 100 Hz.

Pipeline per control tick (module split after Rhoban placo's humanoid walk, github.com/Rhoban/placo,
with Kajita's preview control for the CoM):

1. footsteps from the velocity command (:class:`walk_engine.footsteps.FootstepPlanner`);
2. ZMP reference under the support foot, linear across double support;
3. CoM from Kajita's preview control (:class:`walk_engine.preview.ZmpPreview`, Kajita et al.,
   ICRA 2003) with z_c = ``com_height``;
4. swing foot: minimum-jerk horizontal motion and an apex plateau (:mod:`walk_engine.swing`);
5. body: the torso is placed so that the *whole-body* CoM of a nominal stance (NumPy FK of the
   robot's URDF inertials, :class:`walk_engine.kinematics.BodyModel`) lies on the planned CoM,
   shifted forward by ``com_x_offset`` and pitched by ``torso_pitch``; torso yaw = mean foot yaw;
6. analytic leg IK with the shared HipYawPitch (support-leg weighted,
   :func:`walk_engine.kinematics.legs_ik`);
7. feedback: low-passed gyro (first order, :data:`GYRO_CUTOFF_HZ`) pitch rate -> support ankle
   pitch, roll rate -> support ankle roll and hip roll (rUNSWift Walk2014: Hengst, UNSW
   report, 2014, §5.2; UPenn's DARwIn-OP walk); optional (constructor ``torso_angle_gain``, off by
   default, not one of the 16): measured
   torso roll/pitch error (IMU ``angle`` minus the planned attitude) -> support ankle roll/pitch;
   feed-forward support hip-roll compensation in single support; support weights follow the
   planned ZMP (time-based support switch, see walk_engine/README.md; rUNSWift switches on FSR events);
8. load compensation (fixed, not a gait parameter): the joint servos are soft PD loops
   (``robots.nao.GAINS``: a 0.1 rad error saturates a leg motor), so a support leg sags by
   τ/kp under the body weight -- a stance knee by ≈0.08 rad, which tilts the torso back by as
   much. Each support leg's targets are offset by -τ_ext/kp, where τ_ext = Jᵀ F are the static
   joint torques of its share w of the planned ground reaction M (c̈_x, c̈_y, g) applied at the
   planned ZMP (clipped to that sole). Uses only the robot model and the plan.

The engine is open loop in its plan (the walk frame is the plan's world frame; ground truth is
never read) and closed loop only through the gyro (and the IMU angle if ``torso_angle_gain``). It reads nothing but the observation vector
(layout of ``robots.observation.ObservationLayout``, derived from the robot model, so that no physics engine is
imported). Deterministic: no random numbers, identical observations give identical targets.
"""

from __future__ import annotations

import math

import numpy as np

from common.defaults import CONTROL_DT
from robots import RobotModel, nao_h25
from robots.observation import ObservationLayout
from walk_engine.footsteps import FootstepPlanner, Phase, SupportPolygon, WalkCommand, zmp_reference
from robots.kinematics import BodyModel
from walk_engine.kinematics import (LEG_JOINTS, _fixed_scalar, _fixed_t, _free_hyp, _free_hyp_t,
                                    _load_scalar, _target_scalar, rot_y)
from walk_engine.legs import LegChain
from walk_engine.params import GaitParams, params_for
from walk_engine.preview import ZmpPreview
from walk_engine.swing import min_jerk, swing_pose

#: Preview horizon [s] (1 s is ample for z_c ≈ 0.25 m: the preview gains decay below 1 % of the first
#: one, tests/test_walk_preview.py).
PREVIEW_HORIZON = 1.0
#: First-order low-pass cut-off of the gyro feedback [Hz] (a project setting; rUNSWift Walk2014 filters
#: its gyro at ≈3.5 Hz).
GYRO_CUTOFF_HZ = 5.0
#: Time [s] over which the targets blend from the measured pose at reset into the walking stance.
BLEND_TIME = 0.2
#: Fraction of single support over which the support hip-roll compensation ramps in and out.
HIP_COMP_RAMP = 0.2


def _mat_rows(R: np.ndarray) -> tuple:
    return tuple(tuple(r) for r in R.tolist())


_STANCES: dict = {}


def nominal_stance(robot: RobotModel, com_height: float, feet_spacing: float, torso_pitch: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Where the torso must be for the whole-body CoM to sit at (0, 0, ``com_height``) above feet
    at (0, ±spacing/2, 0), torso pitched by ``torso_pitch``, arms in the crouch pose, for a robot
    with NAO-family legs (``robot.leg_geometry``: the closed form with the shared HipYawPitch).

    Fixed-point iteration on the torso position with the NumPy body model (stage 5 of the module
    docstring: fixed-point iterations with the full-model CoM).

    Returns:
        (c_off (3,): whole-body CoM minus torso origin in the yaw-aligned walk frame [m],
         q (n,): the joint angles of that stance [rad]); cached per robot object and stance, treat as
         read-only.
    """
    key = (id(robot), float(com_height), float(feet_spacing), float(torso_pitch))
    if key not in _STANCES or _STANCES[key][0] is not robot:
        if len(_STANCES) >= 256:
            _STANCES.clear()
        _STANCES[key] = (robot, _nominal_stance(robot, com_height, feet_spacing, torso_pitch))
    return _STANCES[key][1]


def _nominal_stance(robot: RobotModel, com_height, feet_spacing, torso_pitch, legs: dict | None = None):
    """The fixed point of :func:`nominal_stance` for ``robot``: the NAO's legs by the closed form with
    the shared HipYawPitch, or, given ``legs`` (side -> :class:`walk_engine.legs.LegChain`), each leg
    by its own IK."""
    body = BodyModel(robot)
    q = robot.pose("crouch").copy()
    if legs is None:
        iL = robot.joint_index(["L" + j for j in LEG_JOINTS])
        iR = robot.joint_index(["R" + j for j in LEG_JOINTS])
    else:
        idx = {s: robot.joint_index(legs[s].joint_names) for s in "LR"}
    Rt = rot_y(torso_pitch)
    pt = np.array([0.0, 0.0, com_height + 0.05])
    h = feet_spacing / 2.0
    for _ in range(50):
        if legs is None:
            RL = _mat_rows(Rt.T)
            pL = (Rt.T @ (np.array([0.0, h, 0.0]) - pt)).tolist()
            pR = (Rt.T @ (np.array([0.0, -h, 0.0]) - pt)).tolist()
            hyp = 0.5 * (_free_hyp("L", pL, RL) + _free_hyp("R", pR, RL))
            q[iL] = _fixed_scalar("L", pL, RL, hyp)
            q[iR] = _fixed_scalar("R", pR, RL, hyp)
        else:
            for s, y in (("L", h), ("R", -h)):
                q[idx[s]] = legs[s].ik(Rt.T @ (np.array([0.0, y, 0.0]) - pt), Rt.T, q[idx[s]])
        com = pt + Rt @ body.com(q)
        err = com - np.array([0.0, 0.0, com_height])
        err[1] = 0.0
        pt = pt - err
        if np.abs(err).max() < 1e-10:
            break
    com = pt + Rt @ body.com(q)
    c_off = com - pt
    c_off.setflags(write=False)
    q.setflags(write=False)
    return c_off, q


_STANCES: dict = {}


def _nominal_stance_legs(robot: RobotModel, legs: dict, com_height, feet_spacing, torso_pitch):
    """:func:`_nominal_stance` with each leg's own IK, cached per robot and stance."""
    key = (robot.name, com_height, feet_spacing, torso_pitch)
    if key not in _STANCES:
        _STANCES[key] = _nominal_stance(robot, com_height, feet_spacing, torso_pitch, legs)
    return _STANCES[key]


class WalkEngine:
    """ZMP preview-control walk engine (see module docstring) for the NAO-like robot and any humanoid
    whose legs :class:`walk_engine.legs.LegChain` reads (Unitree G1, PAL Talos).

    Args:
        robot: the robot (default :func:`robots.nao_h25`).
        params: the 16 gait parameters of that robot (default its θ0, :func:`walk_engine.params_for`).
        command: the velocity command (default: forward at ``step_length / step_period``).
        dt: control period [s] (must match the world's ``control_dt``, 10 ms).
        load_compensation: offset the support legs' targets by the static sag -τ_ext/kp (stage 8).
        torso_angle_gain: proportional torso-attitude feedback [rad/rad] on the support ankles
            (stage 7; 0 = off). Not a gait parameter: on the "real" profile 0.5 takes θ0 from 4/10
            to 0/10 falls (10 seeds); the sim loop goes unstable above ~1.3.

    Use: ``reset(obs)`` then ``step(obs) -> targets`` every ``dt``; also an ``envs.rollout``
    controller (``reset(obs, info)`` ignores ``info``: the engine never reads ground truth).

    Raises:
        ValueError: params not a :class:`GaitParams` of this robot; non-positive dt; negative
            torso_angle_gain; a leg the engine cannot read (:class:`walk_engine.legs.LegChain`).
    """

    def __init__(self, robot: RobotModel | None = None, params: GaitParams | None = None,
                 command: WalkCommand | None = None, dt: float = CONTROL_DT, load_compensation: bool = True,
                 torso_angle_gain: float = 0.0):
        self.robot = robot or nao_h25()
        if params is None:
            params = params_for(self.robot)()
        if not isinstance(params, GaitParams):
            raise ValueError(f"params must be a GaitParams, got {type(params).__name__}")
        if type(params).robot != self.robot.name:
            raise ValueError(f"gait parameters of robot {type(params).robot!r} given for robot {self.robot.name!r} "
                             f"(use walk_engine.params_for(robot))")
        if not (dt > 0):
            raise ValueError(f"dt must be positive, got {dt}")
        if not (math.isfinite(torso_angle_gain) and torso_angle_gain >= 0):
            raise ValueError(f"torso_angle_gain must be a finite number >= 0, got {torso_angle_gain}")
        self.params = params
        self.command = command or WalkCommand()
        self.dt = float(dt)
        r = self.robot
        self._obs = ObservationLayout(r).slices
        act = r.actuated_joint_names
        # The NAO's legs share HipYawPitch (closed form of walk_engine.kinematics); any other robot's
        # 6-DoF legs are solved one by one (walk_engine.legs: closed form or damped least squares).
        self._generic = r.leg_geometry is None
        if self._generic:
            self._legs = {s: LegChain(r, s) for s in "LR"}
            leg_names = {s: self._legs[s].joint_names for s in "LR"}
            self._iL = np.array([act.index(n) for n in leg_names["L"]])
            self._iR = np.array([act.index(n) for n in leg_names["R"]])
            lg = self._legs["L"]
            self._fb = (lg.hip_roll, lg.ankle_pitch, lg.ankle_roll)
        else:
            leg_names = {s: [s + j for j in LEG_JOINTS] for s in "LR"}
            self._iL = np.array([act.index(n) for n in leg_names["L"]])
            self._iR = np.array([act.index(n) for n in leg_names["R"][1:]])  # RHipYawPitch follows
            self._fb = (1, 4, 5)
        self._lo = r.lower[r.actuated_index]
        self._hi = r.upper[r.actuated_index]
        self._base_list = r.pose("crouch", actuated=True).tolist()  # arms and head
        self._iL_list, self._iR_list = self._iL.tolist(), self._iR.tolist()
        self._lo_list, self._hi_list = self._lo.tolist(), self._hi.tolist()
        self._alpha = 1.0 - math.exp(-2.0 * math.pi * GYRO_CUTOFF_HZ * self.dt)
        self.load_compensation = bool(load_compensation)
        self.torso_angle_gain = float(torso_angle_gain)
        self._inv_kp = {s: (1.0 / r.kp[r.joint_index(leg_names[s])]).tolist() for s in "LR"}
        self._mass = r.total_mass
        self._sole = SupportPolygon.for_robot(r)
        stance = (params.com_height, params.feet_spacing, params.torso_pitch)
        if self._generic:
            self.c_off, self.q_nominal = _nominal_stance_legs(r, self._legs, *stance)
            idx = {s: r.joint_index(leg_names[s]) for s in "LR"}
            self._q_leg0 = {s: np.array(self.q_nominal[idx[s]]) for s in "LR"}
        else:
            self.c_off, self.q_nominal = nominal_stance(r, *stance)  # cached
        self.reset()

    # ------------------------------------------------------------------ control
    def set_command(self, command: WalkCommand) -> None:
        """Change the velocity command (ramped in from the next planned step on)."""
        self.command = command
        self.planner.set_command(command)

    def request_stop(self) -> None:
        """Stop walking: ramp down, bring the feet together, stand."""
        self.planner.request_stop()

    def reset(self, obs: np.ndarray | None = None, info: dict | None = None) -> None:
        """Start a new walk from standing. ``obs`` (optional) gives the measured joint angles to
        blend from; ``info`` is accepted for ``envs.rollout`` and ignored."""
        del info
        p = self.params
        self.planner = FootstepPlanner(p, self.command)
        self.preview = ZmpPreview(p.com_height, p.preview_log10_R, self.dt, PREVIEW_HORIZON)
        self.n_prev = self.preview.n
        self.k = 0
        self.phases: list[Phase] = []
        self._ph_i = 0
        cap = 4096
        self._zbuf = np.empty((cap, 2))
        self._zk0 = 0  # tick index of _zbuf[0]
        self._zn = 0  # filled rows
        self._extend_zmp(self.n_prev + 2)
        self.preview.reset(self._zbuf[0])
        self._gyro = [0.0, 0.0, 0.0]
        self._q_start = None
        if obs is not None:
            self._q_start = np.asarray(obs, float)[self._obs["q"]][self.robot.actuated_index].tolist()
        self._log: list[tuple] = []
        self.last_targets = None
        if self._generic:
            self._q_leg = {s: self._q_leg0[s].copy() for s in "LR"}  # warm starts of the leg IK

    # ------------------------------------------------------------------ planning helpers
    def _extend_zmp(self, upto_k: int) -> None:
        """Plan phases until the ZMP reference is known for ticks < ``upto_k``."""
        dt = self.dt
        while self._zk0 + self._zn < upto_k:
            if self.phases and not math.isfinite(self.phases[-1].t1):
                ph = self.phases[-1]  # endless stand: keep sampling it
                k_a = self._zk0 + self._zn
                k_b = upto_k
            else:
                ph = self.planner.next_phase()
                self.phases.append(ph)
                k_a = max(int(math.ceil(ph.t0 / dt - 1e-9)), self._zk0 + self._zn)
                k_b = int(math.ceil(ph.t1 / dt - 1e-9)) if math.isfinite(ph.t1) else max(upto_k, k_a)
            if k_b <= k_a:
                continue
            vals = zmp_reference(ph, np.arange(k_a, k_b) * dt)
            self._append(vals)

    def _append(self, vals: np.ndarray) -> None:
        n = len(vals)
        if self._zn + n > len(self._zbuf):
            # drop the past (keep the current tick), grow if still too small
            drop = max(0, self.k - self._zk0)
            keep = self._zbuf[drop:self._zn].copy()
            self._zk0 += drop
            self._zn = len(keep)
            cap = max(len(self._zbuf), 2 * (self._zn + n))
            self._zbuf = np.empty((cap, 2))
            self._zbuf[:self._zn] = keep
        self._zbuf[self._zn:self._zn + n] = vals
        self._zn += n

    def _phase_at(self, t: float) -> Phase:
        i = self._ph_i
        ph = self.phases
        while ph[i].t1 <= t + 1e-12 and i + 1 < len(ph):
            i += 1
        self._ph_i = i
        return ph[i]

    def feet_at(self, ph: Phase, t: float) -> tuple[tuple, tuple]:
        """Planned sole poses (x, y, z, yaw) of the left and right foot at time t in phase ph."""
        p = self.params
        out = {}
        for side in "LR":
            if ph.kind == "ss" and side == ph.swing:
                s = (t - ph.t0) / (ph.t1 - ph.t0)
                out[side] = swing_pose(ph.feet[side], ph.feet_end[side], s, p.step_height, p.swing_apex_plateau)
            else:
                x, y, yaw = ph.feet_end[side]
                out[side] = (x, y, 0.0, yaw)
        return out["L"], out["R"]

    # ------------------------------------------------------------------ the tick
    # Over 80 lines by design: the control step of every episode, run 100 times per simulated second,
    # reads best as the one pass it is (stages in order, commented); helpers would add calls on the
    # hot path and scatter state that the stages share.
    def step(self, obs: np.ndarray) -> np.ndarray:
        """One control tick.

        Args:
            obs: the world's observation vector, shape (62,) for the NAO (layout of
                ``robots.observation.ObservationLayout``); only ``gyro``, ``angle`` and ``fsr`` (logged) are
                read (and ``q`` at reset).

        Returns:
            Joint targets [rad], shape (23,), ``robot.actuated_joint_names`` order, within the
            joint limits; meant for the next ``dt``.
        """
        p = self.params
        k = self.k
        g = obs[self._obs["gyro"]].tolist()
        a = self._alpha
        gf = self._gyro
        gf[0] += a * (g[0] - gf[0])
        gf[1] += a * (g[1] - gf[1])
        gf[2] += a * (g[2] - gf[2])
        # preview: x_k -> x_{k+1}; the targets are for the end of this control period
        self._extend_zmp(k + self.n_prev + 2)
        j = k - self._zk0
        x = self.preview.step(self._zbuf[j:j + self.n_prev + 1]).tolist()
        self.k = k = k + 1
        t = k * self.dt
        ph = self._phase_at(t)
        fL, fR = self.feet_at(ph, t)
        wL = ph.weight_left(t)
        # torso pose in the walk frame
        yaw = fL[3] + ((fR[3] - fL[3] + math.pi) % (2.0 * math.pi) - math.pi) / 2.0
        cy, sy = math.cos(yaw), math.sin(yaw)
        ox = p.com_x_offset - self.c_off[0]
        oy = -self.c_off[1]
        tx = x[0][0] + cy * ox - sy * oy
        ty = x[0][1] + sy * ox + cy * oy
        tz = p.com_height - self.c_off[2]
        cp, sp = math.cos(p.torso_pitch), math.sin(p.torso_pitch)
        # R_t = Rz(yaw) Ry(pitch); feet in the torso frame: R_t^T (p - p_t), R_t^T Rz(yaw_f)
        targets = []
        for f in (fL, fR):
            dx, dy, dz = f[0] - tx, f[1] - ty, f[2] - tz
            ux, uy = cy * dx + sy * dy, -sy * dx + cy * dy  # Rz(yaw)^T d
            pos = [cp * ux - sp * dz, uy, sp * ux + cp * dz]  # Ry(pitch)^T
            a = f[3] - yaw
            ca, sa = math.cos(a), math.sin(a)
            # Ry(pitch)^T Rz(a)
            rows = ((cp * ca, -cp * sa, -sp), (sa, ca, 0.0), (sp * ca, -sp * sa, cp))
            targets.append((pos, rows))
        if self._generic:
            hyp = 0.0
            legs, ql = self._legs, self._q_leg
            ql["L"] = legs["L"].ik(targets[0][0], targets[0][1], ql["L"])
            ql["R"] = legs["R"].ik(targets[1][0], targets[1][1], ql["R"])
            qL, qR = ql["L"].tolist(), ql["R"].tolist()
        else:
            tL = _target_scalar("L", *targets[0])
            tR = _target_scalar("R", *targets[1])
            hyp = wL * _free_hyp_t("L", tL) + (1.0 - wL) * _free_hyp_t("R", tR)
            qL = _fixed_t("L", tL, hyp)
            qR = _fixed_t("R", tR, hyp)
        if self.load_compensation:
            self._compensate(qL, qR, wL, x, fL, fR, tx, ty, tz, cy, sy, cp, sp)
        # feedback (as in rUNSWift Walk2014 and the B-Human walk): + pitch rate -> + ankle pitch, + roll rate -> + rolls
        gx, gy = gf[0], gf[1]
        wR = 1.0 - wL
        hr, ap, ar = self._fb  # hip roll, ankle pitch, ankle roll in the leg vectors
        if self.torso_angle_gain:
            ang = obs[self._obs["angle"]]
            er, ep = self.torso_angle_gain * ang[0], self.torso_angle_gain * (ang[1] - p.torso_pitch)
            qL[ap] += wL * ep
            qR[ap] += wR * ep
            qL[ar] += wL * er
            qR[ar] += wR * er
        qL[ap] += wL * p.gyro_ankle_pitch_gain * gy
        qR[ap] += wR * p.gyro_ankle_pitch_gain * gy
        qL[ar] += wL * p.gyro_ankle_roll_gain * gx
        qR[ar] += wR * p.gyro_ankle_roll_gain * gx
        qL[hr] += wL * p.gyro_hip_roll_gain * gx
        qR[hr] += wR * p.gyro_hip_roll_gain * gx
        if ph.kind == "ss" and p.support_hip_roll_comp != 0.0:
            s = (t - ph.t0) / (ph.t1 - ph.t0)
            ramp = min_jerk(min(s, 1.0 - s) / HIP_COMP_RAMP)
            if ph.support == "L":
                qL[hr] += p.support_hip_roll_comp * ramp
            else:
                qR[hr] -= p.support_hip_roll_comp * ramp
        out = self._base_list.copy()
        for i, v in zip(self._iL_list, qL):
            out[i] = v
        for i, v in zip(self._iR_list, qR if self._generic else qR[1:]):
            out[i] = v
        if self._q_start is not None and t < BLEND_TIME:
            s = min_jerk(t / BLEND_TIME)
            out = [q0 + s * (v - q0) for q0, v in zip(self._q_start, out)]
        out = np.array([lo if v < lo else (hi if v > hi else v) for v, lo, hi in zip(out, self._lo_list, self._hi_list)])
        zr = self._zbuf[j + 1].tolist()
        fsr = obs[self._obs["fsr"]].tolist()
        self._log.append((t, x[0][0], x[0][1], x[1][0], x[1][1], x[2][0], x[2][1], zr[0], zr[1], wL,
                          fL[0], fL[1], fL[2], fR[0], fR[1], fR[2], tx, ty, gx, gy, fsr[0], fsr[1], hyp))
        self.last_targets = out
        return out

    __call__ = step

    def _compensate(self, qL, qR, wL, x, fL, fR, tx, ty, tz, cy, sy, cp, sp) -> None:
        """Stage 8: subtract the static sag τ_ext/kp from the support legs' targets (in place)."""
        k = self.params.com_height / 9.81
        zx, zy = x[0][0] - k * x[2][0], x[0][1] - k * x[2][1]  # planned ZMP (cart-table)
        M = self._mass
        hyp = 0.0
        for side, q, f, w in (("L", qL, fL, wL), ("R", qR, fR, 1.0 - wL)):
            if w <= 0.0:
                continue
            # the ZMP clipped to this sole's rectangle
            c, s = math.cos(f[3]), math.sin(f[3])
            dx, dy = zx - f[0], zy - f[1]
            lx, ly = c * dx + s * dy, -s * dx + c * dy
            sp_ = self._sole
            lx = min(max(lx, sp_.back), sp_.front)
            ly = min(max(ly, -sp_.inner), sp_.outer) if side == "L" else min(max(ly, -sp_.outer), sp_.inner)
            px, py = f[0] + c * lx - s * ly, f[1] + s * lx + c * ly
            F = (w * M * x[2][0], w * M * x[2][1], w * M * 9.81)
            # into the torso frame: Ry(pitch)^T Rz(yaw)^T
            ux, uy, uz = cy * (px - tx) + sy * (py - ty), -sy * (px - tx) + cy * (py - ty), -tz
            cop = (cp * ux - sp * uz, uy, sp * ux + cp * uz)
            gx, gy = cy * F[0] + sy * F[1], -sy * F[0] + cy * F[1]
            Ft = (cp * gx - sp * F[2], gy, sp * gx + cp * F[2])
            ik = self._inv_kp[side]
            if self._generic:  # every leg joint has its own motor
                tau = self._legs[side].load_torques(q, cop, Ft).tolist()
                for j in range(6):
                    q[j] -= tau[j] * ik[j]
                continue
            tau = _load_scalar(side, q, cop, Ft)
            for j in range(1, 6):
                q[j] -= tau[j] * ik[j]
            hyp += tau[0] * ik[0]
        if self._generic:
            return
        qL[0] -= hyp
        qR[0] -= hyp

    # ------------------------------------------------------------------ diagnostics
    LOG_FIELDS = ("t", "com_x", "com_y", "com_vx", "com_vy", "com_ax", "com_ay", "zmp_ref_x", "zmp_ref_y",
                  "weight_left", "foot_L_x", "foot_L_y", "foot_L_z", "foot_R_x", "foot_R_y", "foot_R_z",
                  "torso_x", "torso_y", "gyro_f_x", "gyro_f_y", "fsr_L", "fsr_R", "hyp")

    def diagnostics(self) -> dict:
        """What the engine planned, per tick so far, for plots and Rerun (walk frame, SI units).

        Returns:
            dict of arrays of shape (K,) named by :attr:`LOG_FIELDS` (``t`` [s] is the time the
            targets are meant for; ``com_*`` planned CoM position/velocity/acceleration;
            ``zmp_ref_*`` the reference; ``zmp_x/y`` the cart-table ZMP of the plan; feet sole
            positions; ``torso_*`` torso origin target; ``gyro_f_*`` low-passed gyro; ``fsr_*``
            measured foot forces [N]; ``hyp`` shared HipYawPitch [rad]), plus ``footsteps``: a list
            of dicts (kind, t0, t1, support, feet at the end, ZMP reference at start and end).
        """
        arr = np.array(self._log, dtype=float).reshape(-1, len(self.LOG_FIELDS))
        out = {n: arr[:, i].copy() for i, n in enumerate(self.LOG_FIELDS)}
        g = 9.81
        out["zmp_x"] = out["com_x"] - self.params.com_height / g * out["com_ax"]
        out["zmp_y"] = out["com_y"] - self.params.com_height / g * out["com_ay"]
        out["footsteps"] = [
            {"kind": ph.kind, "t0": ph.t0, "t1": ph.t1 if math.isfinite(ph.t1) else None, "support": ph.support,
             "feet": {s: list(v) for s, v in ph.feet_end.items()}, "zmp0": list(ph.zmp0), "zmp1": list(ph.zmp1)}
            for ph in self.phases]
        return out
