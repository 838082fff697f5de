"""The ZMP walk engine vectorized over a batch of gaits, for population-batched evaluation.

:class:`BatchWalkEngine` steps B gaits at once: the per-tick stages of
:class:`walk_engine.engine.WalkEngine` (gyro low-pass, Kajita preview control, swing foot, torso
placement, analytic leg IK with the shared HipYawPitch, load compensation, gyro feedback, hip-roll
compensation, start blend, joint limits) run on arrays of shape (B,), with **the same floating-point
operations in the same order** as the scalar engine, so each episode's targets are bit-identical to
its own ``WalkEngine`` (``tests/test_batch.py``):

* the arithmetic is the scalar code's expressions evaluated on arrays (IEEE-754 elementwise
  operations round the same way; ``np.sqrt`` and ``np.remainder`` are exact like ``math.sqrt`` and
  Python's ``%``);
* transcendental functions go through ``math`` element by element (:func:`common.spatial.libm`):
  NumPy's SIMD ``arctan2``/``arccos`` differ from libm in the last bit on AVX-512 machines;
* the tiny matrix products of the preview controller are ``np.matmul`` on stacks, which calls the
  same BLAS routine per item as the scalar engine's ``@``;
* what changes only at phase boundaries (footstep planning, ZMP reference, the phase's feet and
  weights) stays with one scalar engine per gait and is read when a phase starts.

Not batched: ``torso_angle_gain`` (off by default) and the engine's diagnostics log.
"""

from __future__ import annotations

import math

import numpy as np

from common.defaults import CONTROL_DT
from common.spatial import libm
from robots import RobotModel
from walk_engine.engine import BLEND_TIME, HIP_COMP_RAMP, WalkEngine
from walk_engine.kinematics import _C45, HIP_OFFSET_Y, HIP_OFFSET_Z, L1, L2, LEG_REACH, MIN_REACH, REACH_CLIP, _hip_frame
from walk_engine.params import GaitParams

_PI = math.pi


_m = libm


def _cos_sin(a) -> tuple[np.ndarray, np.ndarray]:
    """``math.cos`` and ``math.sin`` element by element (one conversion for both)."""
    v = np.asarray(a, dtype=float).tolist()
    return (np.fromiter(map(math.cos, v), float, count=len(v)), np.fromiter(map(math.sin, v), float, count=len(v)))


def _min_jerk(s: np.ndarray) -> np.ndarray:
    """:func:`walk_engine.swing.min_jerk` on arrays."""
    s = np.where(s < 0.0, 0.0, np.where(s > 1.0, 1.0, s))
    return s * s * s * (10.0 + s * (-15.0 + 6.0 * s))


def _principal(a: np.ndarray) -> np.ndarray:
    """:func:`walk_engine.kinematics._principal` on arrays."""
    return np.where(a > _PI / 2, a - _PI, np.where(a < -_PI / 2, a + _PI, a))


def _knee(d: np.ndarray) -> np.ndarray:
    c = (d * d - L1 * L1 - L2 * L2) / (2.0 * L1 * L2)
    return _m(math.acos, np.maximum(-1.0, np.minimum(1.0, c)))


def _target(sg: np.ndarray, p, R):
    """:func:`walk_engine.kinematics._target_scalar` on arrays (``sg`` per element: +1 left, -1 right)."""
    x, y, z, rows = _hip_frame(sg, p, R)
    d = np.sqrt(x * x + y * y + z * z)
    far = d > REACH_CLIP * LEG_REACH
    near = ~far & (d < MIN_REACH)
    if far.any() or near.any():
        with np.errstate(all="ignore"):
            k = np.where(far, REACH_CLIP * LEG_REACH / d, MIN_REACH / d)
        tiny = near & ~(d > 1e-12)
        scale = far | (near & ~tiny)
        x, y, z = (np.where(scale, v * k, v) for v in (x, y, z))
        x, y, z = np.where(tiny, 0.0, x), np.where(tiny, 0.0, y), np.where(tiny, -MIN_REACH, z)
    return x, y, z, rows


def _free_hyp(sg: np.ndarray, tgt) -> np.ndarray:
    """:func:`walk_engine.kinematics._free_hyp_t` on arrays (``sg`` per element: +1 left, -1 right)."""
    x, y, z, Rp = tgt
    pa1 = -(Rp[0][1] * x + Rp[1][1] * y + Rp[2][1] * z)
    pa2 = -(Rp[0][2] * x + Rp[1][2] * y + Rp[2][2] * z)
    q5 = _principal(_m(math.atan2, pa1, pa2))
    c5, s5 = _cos_sin(q5)
    a = _m(math.atan2, -(Rp[0][1] * c5 - Rp[0][2] * s5), Rp[1][1] * c5 - Rp[1][2] * s5)
    return np.where(sg > 0, -a, a)


def _fixed(sg: np.ndarray, tgt, hyp) -> list:
    """:func:`walk_engine.kinematics._fixed_t` on arrays: the six leg angles."""
    x, y, z, Rp = tgt
    phi = np.where(sg > 0, -hyp, hyp)
    cp, sp = _cos_sin(phi)
    x, y = cp * x + sp * y, -sp * x + cp * y
    n0, n1, n2 = Rp[0][2], Rp[1][2], Rp[2][2]
    n0, n1 = cp * n0 + sp * n1, -sp * n0 + cp * n1
    b = _principal(_m(math.atan2, y, -z))
    cb, sb = _cos_sin(b)
    zr = -y * sb + z * cb
    q3 = _knee(np.sqrt(x * x + zr * zr))
    c3, s3 = _cos_sin(q3)
    q2 = _m(math.atan2, -L2 * s3, L1 + L2 * c3) - _m(math.atan2, x, -zr)
    n1r, n2r = n1 * cb + n2 * sb, -n1 * sb + n2 * cb
    q5 = _m(math.atan2, -n1r, np.sqrt(n0 * n0 + n2r * n2r))
    q4 = _m(math.atan2, n0, n2r) - q2 - q3
    return [hyp, np.where(sg > 0, b + _PI / 4, b - _PI / 4), q2, q3, q4, q5]


def _load(sg: np.ndarray, q, c, F) -> list:
    """:func:`walk_engine.kinematics._load_scalar` on arrays: external torques on the six joints."""
    q0, q1, q2, q3, q4, _ = q
    ux, uy, uz = 0.0, _C45, -sg * _C45
    co, si = _cos_sin(q0)
    C = 1.0 - co
    r0 = (co + ux * ux * C, uy * ux * C + uz * si, uz * ux * C - uy * si)
    r1 = (ux * uy * C - uz * si, co + uy * uy * C, uz * uy * C + ux * si)
    r2 = (ux * uz * C + uy * si, uy * uz * C - ux * si, co + uz * uz * C)
    c1, s1 = _cos_sin(q1)
    ay = (r1[0] * c1 + r2[0] * s1, r1[1] * c1 + r2[1] * s1, r1[2] * c1 + r2[2] * s1)
    az = (-r1[0] * s1 + r2[0] * c1, -r1[1] * s1 + r2[1] * c1, -r1[2] * s1 + r2[2] * c1)
    ax = r0
    hx, hy, hz = 0.0, sg * HIP_OFFSET_Y, -HIP_OFFSET_Z
    b2, a2 = _cos_sin(q2)
    kx = hx - L1 * (a2 * ax[0] + b2 * az[0])
    ky = hy - L1 * (a2 * ax[1] + b2 * az[1])
    kz = hz - L1 * (a2 * ax[2] + b2 * az[2])
    q23 = q2 + q3
    b3, a3 = _cos_sin(q23)
    nx = kx - L2 * (a3 * ax[0] + b3 * az[0])
    ny = ky - L2 * (a3 * ax[1] + b3 * az[1])
    nz = kz - L2 * (a3 * ax[2] + b3 * az[2])
    q234 = q2 + q3 + q4
    b4, a4 = _cos_sin(q234)
    ar = (b4 * ax[0] - a4 * az[0], b4 * ax[1] - a4 * az[1], b4 * ax[2] - a4 * az[2])
    Fx, Fy, Fz = F
    cx, cy, cz = c

    def tq(a, px, py, pz):
        dx, dy, dz = cx - px, cy - py, cz - pz
        return a[0] * (dy * Fz - dz * Fy) + a[1] * (dz * Fx - dx * Fz) + a[2] * (dx * Fy - dy * Fx)

    return [tq((ux, uy, uz), hx, hy, hz), tq(ax, hx, hy, hz), tq(ay, hx, hy, hz), tq(ay, kx, ky, kz),
            tq(ay, nx, ny, nz), tq(ar, nx, ny, nz)]




class BatchWalkEngine:
    """B gaits of the ZMP walk engine stepped together (see the module docstring).

    Args:
        robot: the robot (all gaits walk the same robot).
        params: B :class:`GaitParams`.
        dt: control period [s].

    Use: ``reset(obs)`` with the B first observations (n_obs columns), then every control step
    ``step(obs, idx)`` with the observations of all B episodes and the indices of the active ones;
    it returns their targets (len(idx), 23), each row bit-identical to what episode i's own
    ``WalkEngine(robot, params[i], dt=dt)`` returns for ``obs[i]`` (after ``reset(obs[i])``). Every
    active episode must be stepped every tick (the batch shares one clock).

    Raises:
        ValueError: no gaits, or a params entry that is not a :class:`GaitParams`.
    """

    def __init__(self, robot: RobotModel, params: list[GaitParams], dt: float = CONTROL_DT):
        if not params:
            raise ValueError("BatchWalkEngine needs at least one gait")
        self.engines = [WalkEngine(robot, p, dt=dt) for p in params]  # planners, stance, constants
        self.size = B = len(self.engines)
        self.robot, self.dt = robot, float(dt)
        e0 = self.engines[0]
        self._obs = e0._obs
        self._alpha = e0._alpha
        self._base = np.array(e0._base_list)
        self._iL, self._iR = np.array(e0._iL_list), np.array(e0._iR_list)
        self._lo, self._hi = np.array(e0._lo_list), np.array(e0._hi_list)
        self._inv_kp = {s: [float(v) for v in e0._inv_kp[s]] for s in "LR"}
        self._mass = e0._mass
        self._sole = e0._sole
        self._load_comp = e0.load_compensation
        P = [e.params for e in self.engines]
        col = lambda f: np.array([f(p) for p in P], dtype=float)  # noqa: E731
        self._ox = np.array([p.com_x_offset - e.c_off[0] for p, e in zip(P, self.engines)])
        self._oy = np.array([-e.c_off[1] for e in self.engines])
        self._tz = np.array([p.com_height - e.c_off[2] for p, e in zip(P, self.engines)])
        self._cp = np.array([math.cos(p.torso_pitch) for p in P])
        self._sp = np.array([math.sin(p.torso_pitch) for p in P])
        self._step_height = col(lambda p: p.step_height)
        self._r = col(lambda p: (1.0 - min(max(p.swing_apex_plateau, 0.0), 0.95)) / 2.0)
        self._g_ap, self._g_ar, self._g_hr = (col(lambda p: p.gyro_ankle_pitch_gain), col(lambda p: p.gyro_ankle_roll_gain),
                                             col(lambda p: p.gyro_hip_roll_gain))
        self._comp = col(lambda p: p.support_hip_roll_comp)
        self._kz = col(lambda p: p.com_height / 9.81)
        # per-episode phase constants (updated when a phase starts), see _load_phase
        self._ph = np.zeros((B, 18))
        self._p0 = np.zeros((B, 3))  # the swing foot's lift-off pose (x, y, yaw)
        self._ph_obj: list = [None] * B
        self._filled = np.zeros(B, dtype=int)

    # ------------------------------------------------------------------ state
    def reset(self, obs: np.ndarray) -> None:
        """Start every walk from standing, blending from the measured joint angles in ``obs`` (B, n_obs)."""
        obs = np.asarray(obs, dtype=float)
        B = self.size
        for e, o in zip(self.engines, obs):
            e.reset(o)
        n = self.engines[0].n_prev
        self._n = n
        cap = 4096
        self._Z = np.zeros((B, cap, 2))
        for i, e in enumerate(self.engines):
            self._copy_zmp(i)
        pv = [e.preview for e in self.engines]
        self._X = np.stack([p.x for p in pv])  # (B, 3, 2)
        self._E = np.stack([p.err_sum for p in pv])  # (B, 2)
        self._CG = np.stack([p._CG for p in pv])  # (B, 4, 3)
        self._A = np.stack([p.A for p in pv])  # (B, 3, 3)
        self._Bc = np.stack([p._Bc for p in pv])  # (B, 3, 1)
        self._Gi = np.array([p.Gi for p in pv], dtype=float)  # (B,)
        self._Gp = np.stack([p.Gp for p in pv])  # (B, N)
        self._gf = np.zeros((B, 3))
        self._qs = np.stack([np.array(e._q_start) for e in self.engines])  # (B, 23)
        self.k = 0
        self._ph_obj = [None] * B
        for i in range(B):
            self._load_phase(i, self.engines[i]._phase_at(0.0))

    def _copy_zmp(self, i: int) -> None:
        e = self.engines[i]
        if e._zk0 != 0:  # pragma: no cover - the planning engines never advance their clock
            raise RuntimeError("planning engine dropped its ZMP past")
        n = e._zn
        if n > self._Z.shape[1]:
            Z = np.zeros((self.size, 2 * n, 2))
            Z[:, :self._Z.shape[1]] = self._Z
            self._Z = Z
        self._Z[i, self._filled[i]:n] = e._zbuf[self._filled[i]:n]
        self._filled[i] = n

    def _load_phase(self, i: int, ph) -> None:
        """Store the constants of episode i's phase ``ph`` (computed in scalar Python, as the scalar
        engine computes them per tick)."""
        if ph is self._ph_obj[i]:
            return
        self._ph_obj[i] = ph
        v = self._ph[i]
        ss = ph.kind == "ss"
        swing = ph.swing
        sL = 1.0 if ph.support == "L" else 0.0
        c0, c1 = ph.weight_line()
        frac = math.isfinite(ph.t1) and ph.t1 > ph.t0  # else footsteps._frac is 1
        v[0], v[1], v[17] = ph.t0, (ph.t1 - ph.t0) if math.isfinite(ph.t1) else 1.0, ph.t1
        v[2], v[3], v[4] = float(ss), c0, c1
        v[5] = float(frac)
        v[6] = {"L": 1.0, "R": -1.0}.get(swing, 0.0)  # +1 swing left, -1 swing right, 0 none
        v[7] = sL
        # feet: standing values from feet_end; the swing foot's start and change
        for k, side in enumerate("LR"):
            x, y, yaw = ph.feet_end[side]
            v[8 + 3 * k: 11 + 3 * k] = (x, y, yaw)
        if swing:
            p0, p1 = ph.feet[swing], ph.feet_end[swing]
            v[14], v[15] = p1[0] - p0[0], p1[1] - p0[1]
            v[16] = (p1[2] - p0[2] + math.pi) % (2.0 * math.pi) - math.pi
            self._p0[i] = p0
        else:
            v[14:17] = 0.0

    # ------------------------------------------------------------------ the tick
    # Over 80 lines by design: the control step of every episode, run 100 times per simulated second,
    # reads best as the one pass it is (stages in order, commented); helpers would add calls on the
    # hot path and scatter state that the stages share.
    def step(self, obs: np.ndarray, idx) -> np.ndarray:
        """One control tick of the episodes ``idx``.

        Args:
            obs: observations (B, n_obs) of every episode (rows not in ``idx`` are ignored).
            idx: indices of the active episodes (all of them at the first tick, then a subset
                that only shrinks).

        Returns:
            Joint targets [rad], shape (len(idx), 23), within the joint limits.
        """
        idx = np.asarray(idx)
        k = self.k
        n = self._n
        dt = self.dt
        g = obs[idx, self._obs["gyro"]]
        gf = self._gf[idx]
        gf = gf + self._alpha * (g - gf)
        self._gf[idx] = gf
        # ZMP reference: plan ahead where needed (scalar planners), then the preview step, batched
        upto = k + n + 2
        for i in idx[self._filled[idx] < upto].tolist():
            self.engines[i]._extend_zmp(upto)
            self._copy_zmp(i)
        ref = self._Z[idx, k:k + n + 1]  # (m, N + 1, 2)
        X = self._X[idx]
        cg = np.matmul(self._CG[idx], X)
        E = self._E[idx] + (cg[:, 0] - ref[:, 0])
        u = -self._Gi[idx, None] * E - cg[:, 1] - np.matmul(self._Gp[idx][:, None, :], ref[:, 1:n + 1])[:, 0]
        X = np.matmul(self._A[idx], X) + self._Bc[idx] * u[:, None, :]
        self._X[idx], self._E[idx] = X, E
        self.k = k = k + 1
        t = k * dt
        # phases (scalar lookups only where a phase ended)
        V = self._ph
        for i in idx[V[idx, 17] <= t + 1e-12].tolist():
            self._load_phase(i, self.engines[i]._phase_at(t))
        v = V[idx]
        t0, dur, ss, c0, c1, frac, sw = v[:, 0], v[:, 1], v[:, 2] > 0, v[:, 3], v[:, 4], v[:, 5] > 0, v[:, 6]
        s = (t - t0) / dur
        wL = c0 + c1 * np.where(frac, np.minimum(1.0, np.maximum(0.0, s)), 1.0)
        # feet (walk frame): the swing foot on its minimum-jerk path
        h = _min_jerk(s)
        r = self._r[idx]
        zh = self._step_height[idx]
        z_sw = np.where(s <= r, zh * _min_jerk(s / r), np.where(s >= 1.0 - r, zh * _min_jerk((1.0 - s) / r), zh))
        p0 = self._p0[idx]
        x_sw, y_sw, yaw_sw = p0[:, 0] + h * v[:, 14], p0[:, 1] + h * v[:, 15], p0[:, 2] + h * v[:, 16]
        feet = []
        for kk, sgn in enumerate((1.0, -1.0)):
            m = ss & (sw == sgn)
            feet.append((np.where(m, x_sw, v[:, 8 + 3 * kk]), np.where(m, y_sw, v[:, 9 + 3 * kk]),
                         np.where(m, z_sw, 0.0), np.where(m, yaw_sw, v[:, 10 + 3 * kk])))
        fL, fR = feet
        yaw = fL[3] + ((fR[3] - fL[3] + math.pi) % (2.0 * math.pi) - math.pi) / 2.0
        cy, sy = _cos_sin(yaw)
        ox, oy = self._ox[idx], self._oy[idx]
        x0 = X[:, 0]
        tx = x0[:, 0] + cy * ox - sy * oy
        ty = x0[:, 1] + sy * ox + cy * oy
        tz = self._tz[idx]
        cp, sp = self._cp[idx], self._sp[idx]
        # both legs at once: arrays (2m,), the left legs first (sg +1), then the right ones (sg -1)
        m = len(idx)
        two = lambda v: np.concatenate([v, v])  # noqa: E731 - a per-episode value for both legs
        f = [np.concatenate([fL[c], fR[c]]) for c in range(4)]
        cy2, sy2, tx2, ty2, tz2, cp2, sp2 = (two(v) for v in (cy, sy, tx, ty, tz, cp, sp))
        dx, dy, dz = f[0] - tx2, f[1] - ty2, f[2] - tz2
        ux, uy = cy2 * dx + sy2 * dy, -sy2 * dx + cy2 * dy
        pos = [cp2 * ux - sp2 * dz, uy, sp2 * ux + cp2 * dz]
        a = f[3] - two(yaw)
        ca, sa = _cos_sin(a)
        rows = ((cp2 * ca, -cp2 * sa, -sp2), (sa, ca, 0.0), (sp2 * ca, -sp2 * sa, cp2))
        sg = np.concatenate([np.ones(m), -np.ones(m)])
        tgt = _target(sg, pos, rows)
        fh = _free_hyp(sg, tgt)
        hyp = wL * fh[:m] + (1.0 - wL) * fh[m:]
        q = _fixed(sg, tgt, two(hyp))
        if self._load_comp:
            self._compensate(idx, q, sg, wL, X, f, tx2, ty2, tz2, cy2, sy2, cp2, sp2)
        qL, qR = [v[:m] for v in q], [v[m:] for v in q]
        gx, gy = gf[:, 0], gf[:, 1]
        wR = 1.0 - wL
        gap, gar, ghr = self._g_ap[idx], self._g_ar[idx], self._g_hr[idx]
        qL[4] = qL[4] + wL * gap * gy
        qR[4] = qR[4] + wR * gap * gy
        qL[5] = qL[5] + wL * gar * gx
        qR[5] = qR[5] + wR * gar * gx
        qL[1] = qL[1] + wL * ghr * gx
        qR[1] = qR[1] + wR * ghr * gx
        comp = self._comp[idx]
        hc = ss & (comp != 0.0)
        if hc.any():
            ramp = _min_jerk(np.minimum(s, 1.0 - s) / HIP_COMP_RAMP)
            supL = v[:, 7] > 0
            qL[1] = np.where(hc & supL, qL[1] + comp * ramp, qL[1])
            qR[1] = np.where(hc & ~supL, qR[1] - comp * ramp, qR[1])
        out = np.repeat(self._base[None], len(idx), axis=0)
        out[:, self._iL] = np.stack(qL, axis=1)
        out[:, self._iR] = np.stack(qR[1:], axis=1)
        if t < BLEND_TIME:
            sb = _min_jerk(np.array([t / BLEND_TIME]))[0]
            q0 = self._qs[idx]
            out = q0 + sb * (out - q0)
        lo, hi = self._lo, self._hi
        return np.where(out < lo, lo, np.where(out > hi, hi, out))

    def _compensate(self, idx, q, sg, wL, X, f, tx, ty, tz, cy, sy, cp, sp) -> None:
        """Stage 8 (load compensation) of :meth:`walk_engine.WalkEngine._compensate` on both legs'
        arrays (2m,) at once, left legs first (in place on ``q``)."""
        m = len(idx)
        kz = self._kz[idx]
        x0, x2 = X[:, 0], X[:, 2]
        zx, zy = x0[:, 0] - kz * x2[:, 0], x0[:, 1] - kz * x2[:, 1]
        zx, zy, ax2, ay2 = (np.concatenate([v, v]) for v in (zx, zy, x2[:, 0], x2[:, 1]))
        M = self._mass
        sole = self._sole
        w = np.concatenate([wL, 1.0 - wL])
        on = w > 0.0
        c, s = _cos_sin(f[3])
        dx, dy = zx - f[0], zy - f[1]
        lx, ly = c * dx + s * dy, -s * dx + c * dy
        lx = np.minimum(np.maximum(lx, sole.back), sole.front)
        left = sg > 0
        ly = np.minimum(np.maximum(ly, np.where(left, -sole.inner, -sole.outer)), np.where(left, sole.outer, sole.inner))
        px, py = f[0] + c * lx - s * ly, f[1] + s * lx + c * ly
        F = (w * M * ax2, w * M * ay2, w * M * 9.81)
        ux, uy, uz = cy * (px - tx) + sy * (py - ty), -sy * (px - tx) + cy * (py - ty), -tz
        cop = (cp * ux - sp * uz, uy, sp * ux + cp * uz)
        gx, gy = cy * F[0] + sy * F[1], -sy * F[0] + cy * F[1]
        Ft = (cp * gx - sp * F[2], gy, sp * gx + cp * F[2])
        tau = _load(sg, q, cop, Ft)
        ik = [np.concatenate([np.full(m, self._inv_kp["L"][j]), np.full(m, self._inv_kp["R"][j])]) for j in range(6)]
        for j in range(1, 6):
            q[j] = np.where(on, q[j] - tau[j] * ik[j], q[j])
        h = np.where(on, tau[0] * ik[0], 0.0)
        hyp = 0.0 + h[:m] + h[m:]  # the scalar engine's hyp = 0; += left; += right
        q[0] = q[0] - np.concatenate([hyp, hyp])
