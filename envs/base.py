"""What both worlds share: action and observation layout, the control loop, fall detection.

Timing: physics at ``physics_dt`` (default 1 ms = 1 kHz; explicit PD on the armature-free NAO links is
not accurate at 2 ms, see ``robots.nao.GAINS``), control at ``control_dt`` (10 ms =
100 Hz); each ``step(action)`` holds the joint targets for ``control_dt / physics_dt`` physics
steps, in each of which the PD law ``tau = kp (q* - q) - kd qdot``, clipped to the URDF effort,
acts on every joint (MuJoCo: actuators with that law; PyBullet: the same law in Python with
``TORQUE_CONTROL``).

Action: targets [rad] for the 23 actuated joints (``RobotModel.actuated_joint_names``; the right
HipYawPitch follows the left one), clipped to the joint limits. Wrong shape, NaN or infinity
raise ``ValueError``.

Observation: what a NAO measures, a flat float64 vector whose named fields are given by
:class:`ObservationLayout` (``q`` encoders [rad] (24), ``dq`` joint velocities [rad/s] (24),
``gyro`` torso angular velocity in the torso frame [rad/s] (3), ``acc`` accelerometer (specific
force in the torso frame, ~ +9.81 z when upright) [m/s^2] (3), ``angle`` torso roll and pitch
[rad] (2), ``fsr`` total normal force under the left/right foot [N] (2), ``cop`` centre of
pressure of each foot in its sole frame [m] (4: Lx, Ly, Rx, Ry; 0 without contact)).

Ground truth rides in ``info`` only: ``time`` [s], ``base_pos`` (3, torso origin, world, m),
``base_quat`` (4, w x y z), ``base_linvel``/``base_angvel`` (3, world), ``com`` (3, world, m),
``cop_world`` (3, whole-robot centre of pressure on the ground; zeros and ``cop_valid`` False
without contact),
``terrain_height`` under the torso [m], ``fall_reason`` (None, "torso_low", "tilt", "unstable").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import gymnasium as gym
import numpy as np

from common.defaults import CONTROL_DT, PHYSICS_DT
from common.spatial import quat_to_mat, roll_pitch
from robots import RobotModel, nao_h25
from robots.observation import ObservationLayout
from terrain import Heightfield
from terrain.heightfield import triangulated_height

GRAVITY = 9.81
#: Fall thresholds (a project choice): the torso origin lower than the robot's ``RobotModel.fall_height``
#: above the terrain (the NAO: 0.20 m) or tilted more than this from upright [rad].
FALL_TILT = math.radians(45.0)
#: Joint speeds above this [rad/s] mean the simulation blew up.
UNSTABLE_JOINT_SPEED = 200.0
FOOT_CONTACT_FORCE = 1.0  # [N] a foot with less normal force has no CoP


def make_terrain(terrain) -> Heightfield | None:
    """None/"flat" -> None (a plane); a Heightfield passes; anything else -> ValueError."""
    if terrain is None or (isinstance(terrain, str) and terrain == "flat"):
        return None
    if isinstance(terrain, Heightfield):
        return terrain
    raise ValueError(f"terrain must be None, 'flat' or a terrain.Heightfield, got {terrain!r}")


def ground_height(terrain: Heightfield | None, x, y) -> np.ndarray:
    """Height [m] of ``terrain`` (None: the plane z = 0) at (x, y) [m], scalars or arrays; outside the
    heightfield the nearest edge value."""
    if terrain is None:
        return np.zeros(np.broadcast(x, y).shape)
    hx, hy = terrain.half_extent
    return terrain.height_at(np.clip(x, -hx, hx), np.clip(y, -hy, hy))


class GroundStack:
    """The grounds of B episodes (a :class:`terrain.Heightfield` or None, the plane, each), for the height
    under one point per episode in one vectorized call: what :func:`ground_height` gives for each
    episode alone, bit for bit (:func:`terrain.heightfield.triangulated_height`), for lock-step batches
    (:class:`envs.batch.SimBatch`, whose fall check asks every control step).

    Fields of one shape and cell size (the random surfaces of a world) are stacked once, here; fields of
    several shapes are looked up one by one.

    Args:
        fields: B heightfields or None.
    """

    def __init__(self, fields):
        self.fields = list(fields)
        real = [i for i, f in enumerate(self.fields) if f is not None]
        self.uneven = bool(real)
        self._row = np.full(len(self.fields), -1, dtype=np.intp)  # episode -> row of the stack (-1: plane)
        self._stack = None
        if real and len({(self.fields[i].shape, self.fields[i].cell_size) for i in real}) == 1:
            f0 = self.fields[real[0]]
            self._stack = np.stack([self.fields[i].heights for i in real])
            self._row[real] = np.arange(len(real))
            self._cell, (self._hx, self._hy) = f0.cell_size, f0.half_extent

    def height(self, episodes, x, y) -> np.ndarray:
        """Ground height [m] under (x[j], y[j]) [m] of episode ``episodes[j]``, shape (n,); outside a
        field the nearest edge value (as :func:`ground_height`)."""
        episodes = np.asarray(episodes, dtype=np.intp)
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        if self._stack is None:
            return np.array([float(ground_height(self.fields[i], x[j], y[j])) for j, i in enumerate(episodes.tolist())])
        row = self._row[episodes]
        out = np.zeros(len(episodes))
        on = row >= 0
        if on.any():
            hx, hy = self._hx, self._hy
            out[on] = triangulated_height(self._stack, row[on], np.clip(x[on], -hx, hx), np.clip(y[on], -hy, hy),
                                          self._cell, hx, hy)
        return out


@dataclass
class StepState:
    """Raw state an engine backend reports after a control step (all world frame, SI)."""

    q: np.ndarray
    dq: np.ndarray
    base_pos: np.ndarray
    base_quat: np.ndarray  # w x y z
    base_linvel: np.ndarray  # of the torso origin
    base_angvel: np.ndarray
    accel_point_vel: np.ndarray  # world velocity of the accelerometer point
    foot_force: np.ndarray  # (2,) normal force L, R [N]
    foot_cop_world: np.ndarray  # (2, 3) CoP of each foot (NaN without contact)


class HumanoidEnv(gym.Env):
    """Common control loop of :class:`envs.SimWorld` and :class:`envs.RealWorld` (abstract).

    Args:
        robot: the robot (default :func:`robots.nao_h25`).
        fixed_base: hang the torso at ``hang_height`` [m] (actuator tests; default the robot's
            ``RobotModel.hang_height``); no falls then.
        physics_dt, control_dt: [s]; ``control_dt`` must be a multiple of ``physics_dt``.
        initial_pose: a :meth:`RobotModel.pose` name the robot starts in (standing on the ground).
        max_episode_seconds: truncate after this long (None: never).

    Raises:
        ValueError: inconsistent time steps, unknown pose.
    """

    metadata = {"render_modes": []}
    world = "abstract"

    def __init__(self, robot: RobotModel | None = None, *, fixed_base: bool = False, physics_dt: float = PHYSICS_DT,
                 control_dt: float = CONTROL_DT, initial_pose: str = "crouch", hang_height: float | None = None,
                 max_episode_seconds: float | None = None):
        self.robot = robot or nao_h25()
        n_sub = control_dt / physics_dt
        if physics_dt <= 0 or control_dt <= 0 or abs(n_sub - round(n_sub)) > 1e-9:
            raise ValueError(f"control_dt ({control_dt}) must be a positive multiple of physics_dt ({physics_dt})")
        self.physics_dt, self.control_dt, self.n_substeps = float(physics_dt), float(control_dt), int(round(n_sub))
        self.fixed_base = bool(fixed_base)
        self.hang_height = float(self.robot.hang_height if hang_height is None else hang_height)
        self.fall_height = float(self.robot.fall_height)
        self.initial_pose = initial_pose
        self.q0 = self.robot.pose(initial_pose)
        self.max_episode_seconds = max_episode_seconds
        r = self.robot
        self.action_space = gym.spaces.Box(r.lower[r.actuated_index], r.upper[r.actuated_index], dtype=np.float64)
        self.layout = ObservationLayout(r)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (self.layout.size,), dtype=np.float64)
        self._terrain: Heightfield | None = None
        self._accel_offset = np.array(r.frames["accel"].offset)
        self._step_count = 0
        self._last_obs: np.ndarray | None = None
        self._prev_accel_vel = np.zeros(3)
        self._noise_rng = np.random.default_rng(0)
        self.last_applied = np.zeros(len(r.actuated_joint_names))

    # ---------------------------------------------------------------- engine hooks
    def _reset_world(self, seed: int | None, options: dict) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _advance(self, targets: np.ndarray) -> None:  # pragma: no cover - abstract
        """Run ``n_substeps`` physics steps holding joint ``targets`` (24,)."""
        raise NotImplementedError

    def _state(self) -> StepState:  # pragma: no cover - abstract
        raise NotImplementedError

    def _com(self) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def _sensor_noise(self, obs: dict[str, np.ndarray]) -> None:
        """Hook for the real world's sensor bias and noise (in place)."""

    # ---------------------------------------------------------------- helpers
    @property
    def terrain(self) -> Heightfield | None:
        """The current episode's heightfield (None = flat plane at z = 0)."""
        return self._terrain

    @property
    def time(self) -> float:
        return self._step_count * self.control_dt

    def terrain_height(self, x, y) -> np.ndarray:
        """Ground height [m] at (x, y); outside the heightfield the nearest edge value."""
        return ground_height(self._terrain, x, y)

    def validate_action(self, action) -> np.ndarray:
        """Return the action as float64 (23,) clipped to the joint limits.

        Raises:
            ValueError: wrong shape, or a NaN/infinite entry (named by joint).
        """
        a = np.asarray(action, dtype=np.float64)
        n = self.action_space.shape[0]
        if a.shape != (n,):
            raise ValueError(f"action must have shape ({n},) (targets [rad] for {n} actuated joints), got {a.shape}")
        bad = ~np.isfinite(a)
        if bad.any():
            names = [self.robot.actuated_joint_names[i] for i in np.flatnonzero(bad)]
            raise ValueError(f"action contains NaN or infinite targets for {', '.join(names)}")
        return np.clip(a, self.action_space.low, self.action_space.high)

    def _observe(self, st: StepState) -> np.ndarray:
        R = quat_to_mat(st.base_quat)
        gyro = R.T @ st.base_angvel
        acc_world = (st.accel_point_vel - self._prev_accel_vel) / self.control_dt
        acc = R.T @ (acc_world + np.array([0.0, 0.0, GRAVITY]))
        self._prev_accel_vel = st.accel_point_vel
        roll, pitch = roll_pitch(R)
        cop = np.zeros(4)
        for k, sole in enumerate(("l_sole", "r_sole")):
            if st.foot_force[k] > FOOT_CONTACT_FORCE and np.all(np.isfinite(st.foot_cop_world[k])):
                cop[2 * k: 2 * k + 2] = self._to_sole(sole, st.foot_cop_world[k])[:2]
        fields = {"q": st.q.copy(), "dq": st.dq.copy(), "gyro": gyro, "acc": acc, "angle": np.array([roll, pitch]),
                  "fsr": st.foot_force.copy(), "cop": cop}
        self._sensor_noise(fields)
        return np.concatenate([fields[k] for k in self.layout.sizes])

    def _to_sole(self, sole: str, p_world: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def _info(self, st: StepState, fall_reason: str | None) -> dict:
        f = st.foot_force
        tot = f.sum()
        cop_valid = bool(tot > FOOT_CONTACT_FORCE)
        cop_world = np.zeros(3)
        if cop_valid:
            for k in range(2):
                if f[k] > 0 and np.isfinite(st.foot_cop_world[k, 0]):
                    cop_world += f[k] * st.foot_cop_world[k]
            cop_world /= tot
        return {
            "time": self.time,
            "base_pos": st.base_pos.copy(), "base_quat": st.base_quat.copy(),
            "base_linvel": st.base_linvel.copy(), "base_angvel": st.base_angvel.copy(),
            "com": self._com(), "cop_world": cop_world, "cop_valid": cop_valid,
            "terrain_height": float(self.terrain_height(st.base_pos[0], st.base_pos[1])),
            "fall_reason": fall_reason,
            "applied_action": self.last_applied.copy(),
        }

    def _fall_reason(self, st: StepState) -> str | None:
        check = np.abs(st.dq).max() + np.abs(st.q).max() + np.abs(st.base_pos).max() + np.abs(st.base_quat).max()
        if not np.isfinite(check) or np.abs(st.dq).max() > UNSTABLE_JOINT_SPEED:
            return "unstable"
        if self.fixed_base:
            return None
        if st.base_pos[2] - float(self.terrain_height(st.base_pos[0], st.base_pos[1])) < self.fall_height:
            return "torso_low"
        R = quat_to_mat(st.base_quat)
        if R[2, 2] < math.cos(FALL_TILT):
            return "tilt"
        return None

    # ---------------------------------------------------------------- gymnasium API
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Start an episode. ``seed`` seeds everything random in the episode (terrain, effects,
        sensor noise). ``options`` may hold ``terrain`` (a Heightfield, or None for flat) and
        ``pose`` (a pose name)."""
        super().reset(seed=seed)
        options = dict(options or {})
        if "pose" in options:
            self.q0 = self.robot.pose(options["pose"])
        self._reset_world(seed, options)
        self._step_count = 0
        self.last_applied = self.q0[self.robot.actuated_index].copy()
        st = self._state()
        self._prev_accel_vel = st.accel_point_vel
        obs = self._observe(st)
        self._last_obs = obs
        return obs, self._info(st, None)

    def step(self, action):
        if self._last_obs is None:
            raise RuntimeError("call reset() before step()")
        a = self.validate_action(action)
        self.last_applied = a
        with np.errstate(all="ignore"):
            self._advance(self.robot.expand_action(a))
            self._step_count += 1
            st = self._state()
            reason = self._fall_reason(st)
        if reason == "unstable":
            obs = self._last_obs.copy()  # the physics state is no longer meaningful
            info = {"time": self.time, "fall_reason": reason, "applied_action": a.copy()}
            self._last_obs = None  # the episode must be reset
            return obs, 0.0, True, False, info
        obs = self._observe(st)
        self._last_obs = obs
        info = self._info(st, reason)
        reward = float(st.base_linvel[0])  # forward speed [m/s]; the walk fitness is computed from recordings
        truncated = self.max_episode_seconds is not None and self.time >= self.max_episode_seconds - 1e-9
        return obs, reward, reason is not None, bool(truncated), info


#: The name of this class when the project modelled the NAO only (kept for user code that uses it).
NaoEnv = HumanoidEnv
