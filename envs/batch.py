"""Many episodes of the MuJoCo sim in lock-step: one ``MjModel``, one ``MjData`` per episode.

:class:`SimBatch` runs B episodes of a :class:`envs.SimWorld` side by side (or of a subclass that
says what it changes through ``batch_hooks()``: the identified sim's encoder offsets and series
hinges). Every control step it applies B
actions, advances each ``MjData`` by ``n_substeps`` (``mujoco.mj_step(m, d, nstep)``, one C call per
episode, GIL released) and builds the B observations and ground-truth rows with the per-episode
work cut to array reads, the contact force sums and three 3x3 products; the arithmetic is the same,
operation by operation, as :meth:`envs.HumanoidEnv.step`, so each episode's observations, applied actions,
ground truth and fall decisions are **bit-identical** to stepping a ``SimWorld`` alone
(``tests/test_batch.py``). Episodes that end (a fall, an unstable simulation) leave the active set.

Resets go through the template env itself (a fresh ``MjData`` per episode, or the model the env
builds for the episode's ground), so the initial state is the env's by construction; the template
gets its own model and data back afterwards. The MuJoCo documentation recommends exactly this layout
for parallel rollouts ("Python bindings > rollout": one model, one data per thread); the
``mujoco.rollout`` module itself is open loop and cannot host a controller in the loop.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from common.spatial import cross, quats_to_mats, roll_pitch
from envs.base import (FALL_TILT, FOOT_CONTACT_FORCE, GRAVITY, UNSTABLE_JOINT_SPEED, GroundStack, ground_height,
                       make_terrain)
from envs.mujoco_world import SimWorld, foot_contact_sums
from envs.rollout import gt_row

_COS_TILT = math.cos(FALL_TILT)


class SimBatch:
    """B lock-step episodes of the plain MuJoCo sim ``env`` (see the module docstring).

    Args:
        env: a :class:`envs.SimWorld`, or a subclass with ``batch_hooks()`` (its time steps, robot and
            lookups are shared; its model too unless an episode gets its own ground).
        size: the number of episodes B (>= 1).

    Attributes after :meth:`reset`: ``obs`` (B, n_obs) the latest observations, ``gt`` (B, 19) the
    latest ground-truth rows (:data:`envs.rollout.GT_COLUMNS` order), ``applied`` (B, 23) the last
    applied actions, ``active`` (B,) bool, ``reason`` (list of fall reasons or None).

    Raises:
        TypeError: a subclass of ``SimWorld`` without ``batch_hooks()`` (it may change the physics in
            ways the batch does not know), or another env.
        ValueError: size < 1.
    """

    def __init__(self, env: SimWorld, size: int):
        if type(env) is not SimWorld and not hasattr(env, "batch_hooks"):
            raise TypeError(f"SimBatch runs the plain SimWorld or a subclass with batch_hooks(), got {type(env).__name__}")
        if size < 1:
            raise ValueError(f"batch size must be >= 1, got {size}")
        self.env = env
        self.size = int(size)
        self.model = env.model
        self.models = [env.model] * self.size
        self._fields = [env.terrain] * self.size
        self._grounds = GroundStack(self._fields)
        self._uneven = self._grounds.uneven
        self._fall_height = env.fall_height
        self.datas = [None] * self.size
        # what a subclass changes (SimWorld.batch_hooks): targets minus ctrl_offset go to the servos;
        # the measured angle adds the series hinges (i, qpos address, qvel address); q_offset is added
        # to the observed angles
        hooks = env.batch_hooks() if hasattr(env, "batch_hooks") else {}
        self._ctrl_offset = hooks.get("ctrl_offset")
        self._q_offset = hooks.get("q_offset")
        series = list(hooks.get("series", ()))
        self._series = [(i, k) for k, (i, _, _) in enumerate(series)]
        self._s_qadr = np.array([qa for _, qa, _ in series], dtype=int)
        self._s_dadr = np.array([da for _, _, da in series], dtype=int)
        r = env.robot
        self._lo, self._hi = env.action_space.low, env.action_space.high
        self._na = env.action_space.shape[0]
        self._expand = r.actuated_to_joint
        self._acc_site = env._sites["accel"]
        self._soles = [env._sites["l_sole"], env._sites["r_sole"]]
        self.layout = env.layout
        self.obs = np.zeros((self.size, env.layout.size))
        self.gt = np.full((self.size, 19), np.nan)
        self.applied = np.zeros((self.size, self._na))
        self.active = np.zeros(self.size, dtype=bool)
        self.reason: list = [None] * self.size
        self._prev_acc_vel = np.zeros((self.size, 3))
        self._warn = np.zeros(self.size, dtype=np.int64)
        self._bad = np.array([int(w) for w in SimWorld._BAD])
        self._ground_id, self._geom_foot = env._ground, env._geom_foot.copy()
        # joint addresses as slices where they are contiguous (a view copies faster than a gather)
        self._qadr, self._dadr = (slice(int(a[0]), int(a[-1]) + 1) if np.array_equal(a, np.arange(a[0], a[-1] + 1)) else a
                                  for a in (env._qadr, env._dadr))

    def reset(self, seeds, terrains=None) -> None:
        """Reset episode i with ``seeds[i]``: exactly ``env.reset(seed=seeds[i])``, or with
        ``options={"terrain": terrains[i]}`` when per-episode terrains are given (each such episode
        then has its own ``MjModel``, compiled as the env compiles it).

        Raises:
            ValueError: ``terrains`` of another length than ``seeds``, or not Heightfields/None.
        """
        env = self.env
        own = (env.model, env.data, env._terrain)
        B = self.size
        if terrains is not None and len(terrains) != B:
            raise ValueError(f"{len(terrains)} terrains for {B} episodes")
        try:
            for i, s in enumerate(seeds):
                if terrains is not None:  # SimWorld._reset_world with a terrain option: a model on that ground
                    env._terrain = make_terrain(terrains[i])
                    env._build()
                else:
                    env.data = mujoco.MjData(env.model)
                obs, info = env.reset(seed=s)  # a world may build a model per episode (identified: its ground)
                if env._ground != self._ground_id or not np.array_equal(env._geom_foot, self._geom_foot):
                    raise RuntimeError("a terrain changed the robot's geom ids")  # pragma: no cover
                self.models[i], self.datas[i], self._fields[i] = env.model, env.data, env.terrain
                self.obs[i] = obs
                self.gt[i] = gt_row(info)
                self._prev_acc_vel[i] = env._prev_accel_vel
                self._warn[i] = env._warnings
                self.applied[i] = env.last_applied
                self.reason[i] = None
        finally:
            env.model, env.data, env._terrain = own
        self._grounds = GroundStack(self._fields)
        self._uneven = self._grounds.uneven
        self.active[:] = True

    def terrain(self, i: int):
        """Episode i's heightfield (None: flat)."""
        return self._fields[i]

    # Over 80 lines by design: the control step of every episode, run 100 times per simulated second,
    # reads best as the one pass it is (stages in order, commented); helpers would add calls on the
    # hot path and scatter state that the stages share.
    def step(self, actions: np.ndarray) -> None:
        """Apply ``actions`` (B, 23) [rad] to the active episodes for one control step.

        Updates ``obs``, ``gt``, ``applied``, ``reason`` and ``active`` of the active episodes
        (an inactive episode's row is ignored and left as it was).

        Raises:
            ValueError: wrong shape, or an active row with NaN or infinite targets (named by
                episode and joint), as :meth:`envs.HumanoidEnv.validate_action` raises.
        """
        env = self.env
        m, models = self.model, self.models
        nsub = env.n_substeps
        idx = np.flatnonzero(self.active)
        a = np.asarray(actions, dtype=np.float64)
        if a.shape != (self.size, self._na):
            raise ValueError(f"actions must have shape ({self.size}, {self._na}), got {a.shape}")
        bad = ~np.isfinite(a[idx])
        if bad.any():
            r, c = np.argwhere(bad)[0]
            raise ValueError(f"episode {idx[r]}: action contains NaN or infinite targets for "
                             f"{env.robot.actuated_joint_names[c]}")
        applied = np.clip(a[idx], self._lo, self._hi)
        targets = applied[:, self._expand]
        if self._ctrl_offset is not None:
            targets = targets - self._ctrl_offset
        qadr, dadr, torso = self._qadr, self._dadr, env._torso
        gfoot, ground = env._geom_foot, env._ground
        n = len(idx)
        vel = np.empty((n, 6))
        pos, quat, com = np.empty((n, 3)), np.empty((n, 4)), np.empty((n, 3))
        q, dq = np.empty((n, len(env._qadr))), np.empty((n, len(env._dadr)))
        sq, sdq = np.empty((n, len(self._s_qadr))), np.empty((n, len(self._s_dadr)))
        s_qadr, s_dadr = self._s_qadr, self._s_dadr
        site_pos, site_mat = np.empty((n, m.nsite, 3)), np.empty((n, m.nsite, 9))
        c_g1, c_g2, c_fn, c_pos, c_n = [], [], [], [], np.zeros(n, dtype=np.int64)
        warn = np.empty((n, int(mujoco.mjtWarning.mjNWARNING)), dtype=np.int64)
        body = mujoco.mjtObj.mjOBJ_BODY
        with np.errstate(all="ignore"):
            # per episode: the physics (C) and array reads; the rest is vectorized below
            for j, i in enumerate(idx.tolist()):
                d = self.datas[i]
                d.ctrl[:] = targets[j]
                mj = models[i]
                mujoco.mj_step(mj, d, nstep=nsub)
                mujoco.mj_objectVelocity(mj, d, body, torso, vel[j], 0)
                pos[j], quat[j], com[j] = d.xpos[torso], d.xquat[torso], d.subtree_com[torso]
                site_pos[j], site_mat[j] = d.site_xpos, d.site_xmat
                q[j], dq[j] = d.qpos[qadr], d.qvel[dadr]
                if len(s_qadr):
                    sq[j], sdq[j] = d.qpos[s_qadr], d.qvel[s_dadr]
                warn[j] = d.warning.number
                if d.ncon:  # envs.SimWorld._state: the contacts, summed per foot below
                    con = d.contact
                    c_g1.append(con.geom1)
                    c_g2.append(con.geom2)
                    c_fn.append(d.efc_force[con.efc_address])
                    c_pos.append(con.pos)
                    c_n[j] = d.ncon
            if c_g1:
                force, cop = foot_contact_sums(np.concatenate(c_g1), np.concatenate(c_g2), np.concatenate(c_fn),
                                               np.concatenate(c_pos), gfoot, ground, np.repeat(np.arange(n), c_n), n)
            else:
                force, cop = np.zeros((n, 2)), np.zeros((n, 2, 3))
            cop = np.where(force[:, :, None] > 0, cop / force[:, :, None], np.nan)
        acc_site = site_pos[:, self._acc_site]
        sole_pos, sole_mat = site_pos[:, self._soles], site_mat[:, self._soles]
        ang, lin = vel[:, :3], vel[:, 3:]
        acc_vel = lin + cross(ang, acc_site - pos)
        for i_joint, k in self._series:  # the measured angle of a joint with series hinges: their sum
            q[:, i_joint] += sq[:, k]
            dq[:, i_joint] += sdq[:, k]
        q[warn[:, self._bad].sum(axis=1) > self._warn[idx]] = np.nan  # MuJoCo reset the state after a bad qpos/qvel/qacc: "unstable"
        self.applied[idx] = applied
        # envs.HumanoidEnv._fall_reason
        absmax = (np.abs(dq).max(axis=1) + np.abs(q).max(axis=1) + np.abs(pos).max(axis=1)
                  + np.abs(quat).max(axis=1))
        unstable = ~np.isfinite(absmax) | (np.abs(dq).max(axis=1) > UNSTABLE_JOINT_SPEED)
        R = quats_to_mats(quat)
        if env.fixed_base:
            low = tilt = np.zeros(n, dtype=bool)
        else:
            with np.errstate(all="ignore"):
                if self._uneven:  # each episode's own ground, as HumanoidEnv._fall_reason
                    floor_z = self._grounds.height(idx, pos[:, 0], pos[:, 1])
                else:
                    floor_z = ground_height(None, pos[:, 0], pos[:, 1])
                low = pos[:, 2] - floor_z < self._fall_height
            tilt = ~low & (R[:, 2, 2] < _COS_TILT)
        # envs.HumanoidEnv._observe (the obs of an unstable episode stays the last one)
        ok = ~unstable
        RT = R.transpose(0, 2, 1)
        gyro = np.matmul(RT, ang[:, :, None])[:, :, 0]
        acc_world = (acc_vel - self._prev_acc_vel[idx]) / env.control_dt
        acc = np.matmul(RT, (acc_world + np.array([0.0, 0.0, GRAVITY]))[:, :, None])[:, :, 0]
        roll, pitch = roll_pitch(R)
        cop_s = np.zeros((n, 4))
        for k in (0, 1):
            has = (force[:, k] > FOOT_CONTACT_FORCE) & np.all(np.isfinite(cop[:, k]), axis=1)
            if has.any():
                M = sole_mat[has, k].reshape(-1, 3, 3).transpose(0, 2, 1)
                cop_s[has, 2 * k: 2 * k + 2] = np.matmul(M, (cop[has, k] - sole_pos[has, k])[:, :, None])[:, :2, 0]
        q_obs = q if self._q_offset is None else q + self._q_offset  # HumanoidEnv._sensor_noise of the subclass
        obs = np.concatenate([q_obs, dq, gyro, acc, roll[:, None], pitch[:, None], force, cop_s], axis=1)
        # envs.HumanoidEnv._info: the whole-robot CoP
        tot = force.sum(axis=1)
        cw = np.zeros((n, 3))
        for k in (0, 1):
            use = (force[:, k] > 0) & np.isfinite(cop[:, k, 0])
            cw = cw + np.where(use[:, None], force[:, k, None] * cop[:, k], 0.0)
        with np.errstate(all="ignore"):
            cw = np.where((tot > FOOT_CONTACT_FORCE)[:, None], cw / tot[:, None], np.nan)
        gt = np.concatenate([pos, quat, lin, ang, com, cw], axis=1)
        live = idx[ok]
        self.obs[live] = obs[ok]
        self.gt[live] = gt[ok]
        self._prev_acc_vel[live] = acc_vel[ok]
        for j in np.flatnonzero(unstable | low | tilt).tolist():
            i = idx[j]
            self.reason[i] = "unstable" if unstable[j] else ("torso_low" if low[j] else "tilt")
            self.active[i] = False


