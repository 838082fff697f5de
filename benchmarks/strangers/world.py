"""The strangers' world: the project's PyBullet world with effect profile ``"none"`` and hidden effects
of :mod:`.effects` acting through a PD loop, sensors and model edits of its own.

What it keeps of :class:`envs.bullet_world.NaoRealEnv`: the engine set-up, the URDF, the contact and
heightfield recipe, the state read-out, the fall rules and the gymnasium API. What it replaces:

* :meth:`StrangerWorld._advance` - the servo loop at every physics step (1 ms): the command path
  (transport delay, first-order lag), the PD law per joint with its gains, torque ceilings and
  torque-speed envelope, the gear play of a joint (a massless motor with its own angle, solved by
  backward Euler), the elasto-plastic friction state, then Bullet's ``TORQUE_CONTROL``;
* :meth:`StrangerWorld._sensor_noise` - the encoder reading (the motor angle where the encoder sits on
  the motor shaft, offsets), encoder noise and the torso IMU noise;
* the inertial parameters (a link's CoM and rotational inertia, the torso's mass and CoM) are written
  into the URDF the world loads (a copy of the robot model with edited inertials);
* the ground: foot-ground friction coefficient, a Perlin-noise heightfield per episode
  (:mod:`.ground`).

With no hidden effect and no noise the world is the plain ``NaoRealEnv(profile="none")`` bit for bit
(``tests/test_strangers.py``). Ground truth rides in ``info``: besides the base world's keys,
``q_link`` (24, the links' true angles [rad]) and ``q_motor`` (24, the motor angles where a gear play
acts, else the link angles).
"""

from __future__ import annotations

import copy
import dataclasses
import math
from collections import deque

import numpy as np
import pybullet

from benchmarks.blind.families import ANGLE_NOISE, GYRO_NOISE, NOISE
from envs.bullet_world import NaoRealEnv
from robots import Inertial, nao_h25

from .effects import KINDS, Effect, compile_effects, validate_hidden
from .ground import episode_ground

#: The largest presliding deflection [rad] of a friction the world accepts (its bristle stiffness is
#: lowered for stability where effects add up on one joint; beyond this the friction would be no longer
#: Coulomb-like).
HARD_PRESLIDING = 0.01


def _inertial_robot(robot, effects: list[Effect]):
    """A copy of ``robot`` with the inertial effects written into its link inertials (``robot`` itself
    if there are none): com_offset (CoM += distance * direction, link frame), inertia_scale (all six
    inertia entries x scale), torso_mass (root mass and inertia x scale), torso_com (root CoM shift)."""
    edits = [e for e in effects if e.kind in ("com_offset", "inertia_scale", "torso_mass", "torso_com")]
    if not edits:
        return robot
    joints = {j.child: j for j in robot.joints}
    inert = {j.child: j.inertial for j in robot.joints}
    inert[robot.root] = robot.root_inertial
    for e in edits:
        link = e.target
        i = inert[link]
        if e.kind in ("com_offset", "torso_com"):
            d = e.values["distance"] * np.asarray(e.values["direction"], dtype=float)
            i = Inertial(i.mass, tuple(float(c) for c in np.asarray(i.com) + d), i.inertia)
        elif e.kind == "inertia_scale":
            i = Inertial(i.mass, i.com, tuple(float(v) * e.values["scale"] for v in i.inertia))
        else:  # torso_mass: a denser torso, the same shape
            s = e.values["scale"]
            i = Inertial(i.mass * s, i.com, tuple(float(v) * s for v in i.inertia))
        inert[link] = i
    new_joints = tuple(dataclasses.replace(j, inertial=inert[j.child]) if inert[j.child] is not j.inertial else j
                       for j in joints.values())
    return dataclasses.replace(robot, joints=new_joints, root_inertial=inert[robot.root])


class StrangerWorld(NaoRealEnv):
    """The PyBullet world with the strangers' hidden effects (module docstring).

    Args:
        hidden: hidden effects, a list of dicts ``{"family", "targets", "values"[, "params"]}``
            (:mod:`.effects`); fixed for the world's lifetime (the uneven ground is drawn afresh per
            episode from the episode seed).
        robot: the robot (default :func:`robots.nao_h25`).
        noise: encoder noise standard deviation [rad] (default 1e-3, the blind benchmark's).
        imu_noise: (gyro [rad/s], torso roll/pitch [rad]) noise standard deviations; default the blind
            benchmark's (1e-2, 2e-3) with a floating base, (0, 0) with a fixed one (the torso does not move).
        trace: keep every physics step's applied torques and joint speeds in :attr:`trace` (tests).
        **kwargs: :class:`envs.bullet_world.NaoRealEnv`'s (``fixed_base``, ``terrain``, ``physics_dt``, ...)
            except ``profile`` (always ``"none"``) and ``ground``.

    Attributes:
        hidden: the validated effects, one record per target (``{"family", "targets": [t], "values": [v],
            "params": [{...}]}``, every parameter filled in, absolute units); also written to each recording's
            metadata under ``effects.extra.strangers``.
        servo: the loop constants (:class:`.effects.Servo`), its ``index`` the stability index.
        trace: with ``trace=True``, one (applied torques (24,) [N m], joint speeds (24,) [rad/s]) pair per
            physics step of the current episode.

    Raises:
        ValueError: invalid hidden effects (:func:`.effects.validate_hidden`), effects that would put the
            explicit loop near its stability bound (:func:`.effects.compile_effects`), a negative or
            non-finite noise, ``imu_noise`` not a pair, a ``profile`` or ``ground`` argument, a terrain given
            with ``uneven_ground``, or a latency delay that is not a whole number of physics steps.
    """

    world = "strangers"

    def __init__(self, hidden=(), robot=None, *, noise: float = NOISE, imu_noise: tuple[float, float] | None = None,
                 trace: bool = False, **kwargs):
        for bad in ("profile", "ground"):
            if bad in kwargs:
                raise ValueError(f"StrangerWorld takes no {bad!r} argument: its effects are the hidden ones")
        base = robot or nao_h25()
        fixed_base = bool(kwargs.get("fixed_base", False))
        effects = validate_hidden(hidden, base, fixed_base)
        self.hidden_effects = effects
        self.hidden = [{"family": e.kind, "targets": [e.target], "values": [e.values[e.spec.value.name]],
                        "params": [{k: v for k, v in e.values.items() if k != e.spec.value.name}]} for e in effects]
        ground = [e for e in effects if e.kind == "uneven_ground"]
        if ground:
            if kwargs.get("terrain", "lumpy") != "lumpy":
                raise ValueError("uneven_ground lays its own terrain: leave `terrain` at its default")
            rms, wl = ground[0].values["rms_height"], ground[0].values["wavelength"]
            kwargs["ground"] = lambda seed: episode_ground(seed, rms, wl)
        if imu_noise is not None and (not isinstance(imu_noise, (tuple, list)) or len(imu_noise) != 2):
            raise ValueError(f"imu_noise must be (gyro [rad/s], angle [rad]), got {imu_noise!r}")
        for name, v in (("noise", noise),) + tuple(zip(("gyro noise", "angle noise"), imu_noise or ())):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a finite standard deviation >= 0, got {v!r}")
        super().__init__(_inertial_robot(base, effects), profile="none", **kwargs)
        self.nominal_robot = base
        self.encoder_noise = float(noise)
        if imu_noise is None:
            imu_noise = (0.0, 0.0) if self.fixed_base else (GYRO_NOISE, ANGLE_NOISE)
        self.gyro_noise, self.angle_noise = float(imu_noise[0]), float(imu_noise[1])
        self.keep_trace = bool(trace)
        self.trace: list[tuple[np.ndarray, np.ndarray]] = []
        self._constants(effects)

    # ---------------------------------------------------------------- effect constants
    def _constants(self, effects: list[Effect]) -> None:
        dt = self.physics_dt
        sv = compile_effects(self.robot, effects, dt, presliding=HARD_PRESLIDING)  # the edited inertials
        steps = sv.delay / dt
        if abs(steps - np.rint(steps)) > 1e-6:
            raise ValueError(f"latency_lowpass delay {sv.delay:g} s is not a whole number of physics steps ({dt:g} s)")
        self.servo = sv
        self._delay = int(np.rint(steps))
        self._alpha = 1.0 - math.exp(-dt / sv.time_constant) if sv.time_constant > 0 else None
        self._mu = sv.foot_friction
        self._kp_e, self._kd_e, self._ceil = sv.kp, sv.kd, sv.ceiling
        self._gain = sv.gain if np.any(sv.gain != 1.0) else None
        self._w0 = sv.no_load_speed if np.any(np.isfinite(sv.no_load_speed)) else None
        self._stall = self.robot.effort.copy()
        self._loop_bias = sv.loop_bias if np.any(sv.loop_bias != 0.0) else None
        self._read_bias = sv.read_bias if np.any(sv.read_bias != 0.0) else None
        self._gear = sv.gear
        self._gear_idx = np.array(sorted(sv.gear), dtype=int)
        self._read_motor = np.array([j for j in sorted(sv.gear) if not sv.gear[j][0]], dtype=int)
        self._fric_idx = np.array(sorted(sv.friction), dtype=int)
        rows = [sv.friction[j] for j in self._fric_idx]
        self._fric = np.array(rows, dtype=float).reshape(-1, 6).T if rows else None

    # ---------------------------------------------------------------- engine hooks
    def _reset_world(self, seed, options) -> None:
        super()._reset_world(seed, options)
        self.effects.extra["strangers"] = copy.deepcopy(self.hidden)
        if self._mu is not None:
            r = self.robot
            for foot in ("l_sole", "r_sole"):
                self.client.changeDynamics(self.body, self._link[r.frames[foot].link], lateralFriction=self._mu)
        self._fifo = deque([self.q0.copy() for _ in range(self._delay)])
        self._lp = self.q0.copy()
        # motor angles [rad] and speeds [rad/s] of the geared joints: centred in the gap, at rest
        self._theta = self.q0[self._gear_idx].copy() if len(self._gear_idx) else np.zeros(0)
        self._theta_dot = np.zeros(len(self._gear_idx))
        self._z = np.zeros(len(self._fric_idx))  # bristle deflections [rad]
        self.trace = []

    def _ceiling(self, j: int, s: float, speed: float) -> float:
        """Torque ceiling [N m] (before the torque-constant factor) of joint ``j`` pushing in direction
        ``s`` (+-1) at speed ``speed`` [rad/s]: the saturation ceiling, and in the motoring quadrant
        (s * speed > 0) the torque-speed envelope effort * max(1 - |speed| / omega_0, 0)."""
        c = self._ceil[j]
        if self._w0 is not None and s * speed > 0.0:
            c = min(c, self._stall[j] * max(1.0 - abs(speed) / self._w0[j], 0.0))
        return c

    def _motor_side(self, k: int, j: int, u: float, q: float, dq: float, g: float) -> float:
        """Torque [N m] on the link of the motor-side gear play of joint ``j`` (``k``: its row in the motor
        state; ``u``: the servo's target in motor angle, ``g``: torque-constant factor); advances the
        massless motor by backward Euler: kp (u - x) - kd (x - theta) / dt equals the contact torque
        kc (x - q - s h) + bc ((x - theta) / dt - qdot) when the teeth touch (s: the side), 0 in the gap."""
        dt = self.physics_dt
        _, h, kc, bc = self._gear[j]
        kp, kd, th = g * self._kp_e[j], g * self._kd_e[j], self._theta[k]
        A = kp + kd / dt
        xf = (kp * u + kd * th / dt) / A
        tau, x = 0.0, xf
        if abs(xf - q) > h:
            s = 1.0 if xf > q else -1.0
            xc = (kp * u + (kd + bc) * th / dt + kc * (q + s * h) + bc * dq) / (A + kc + bc / dt)
            tc = kc * (xc - q - s * h) + bc * ((xc - th) / dt - dq)
            if s * tc > 0.0 and s * (xc - q) > h:
                L = g * self._ceiling(j, s, self._theta_dot[k])
                if abs(tc) > L:  # the motor at its ceiling: the contact passes exactly L
                    tc = s * L
                    xc = (tc + kc * (q + s * h) + bc * th / dt + bc * dq) / (kc + bc / dt)
                tau, x = tc, xc
        self._theta_dot[k] = (x - th) / dt
        self._theta[k] = x
        return tau

    def _link_side(self, k: int, j: int, u: float, q: float, dq: float, g: float) -> float:
        """Torque [N m] on the link of the link-side gear play (rigid teeth, play operator) of joint ``j``;
        advances the massless motor (free in the gap: kp (u - x) = kd (x - theta) / dt; at a face: with
        the link, passing the PD torque kp (u - x) - kd qdot if it pushes)."""
        dt = self.physics_dt
        h = self._gear[j][1]
        kp, kd, th = g * self._kp_e[j], g * self._kd_e[j], self._theta[k]
        xf = (kp * u + kd * th / dt) / (kp + kd / dt)
        tau, x = 0.0, xf
        if abs(xf - q) >= h:
            s = 1.0 if xf > q else -1.0
            x = q + s * h
            t = kp * (u - x) - kd * dq
            if s * t > 0.0:
                tau = s * min(abs(t), g * self._ceiling(j, s, dq))
        self._theta_dot[k] = (x - th) / dt
        self._theta[k] = x
        return tau

    def _advance(self, targets: np.ndarray) -> None:
        """Run ``n_substeps`` physics steps holding joint ``targets`` (24,) [rad]: at each step the command
        path (FIFO of ``delay`` steps, then the first-order lag), the PD torque per joint
        tau = gain * clip(kp (u - q - b) - kd qdot, ceilings) (ceilings: the saturation and, motoring, the
        torque-speed envelope), the gear-play joints' torque from their motor model, plus the friction
        torque of the elasto-plastic state, then Bullet's ``TORQUE_CONTROL`` and one ``stepSimulation``."""
        # module-level PyBullet calls with the client id (the BulletClient wrapper costs 1-2 us a call)
        cid, b, idx = self.client._client, self.body, self._jidx
        get_states, set_motors, step = pybullet.getJointStates, pybullet.setJointMotorControlArray, pybullet.stepSimulation
        n, dt = len(idx), self.physics_dt
        kp, kd, ceil, gain, w0, stall = self._kp_e, self._kd_e, self._ceil, self._gain, self._w0, self._stall
        loop_bias, fifo, alpha = self._loop_bias, self._fifo, self._alpha
        gear, fric = list(enumerate(self._gear_idx.tolist())), self._fric
        lo = -ceil
        for _ in range(self.n_substeps):
            cmd = targets
            if self._delay:
                fifo.append(targets)
                cmd = fifo.popleft()
            if alpha is not None:
                self._lp += alpha * (cmd - self._lp)
                cmd = self._lp
            js = get_states(b, idx, physicsClientId=cid)
            q = np.fromiter((s[0] for s in js), float, n)
            dq = np.fromiter((s[1] for s in js), float, n)
            err = cmd - (q + loop_bias) if loop_bias is not None else cmd - q
            if w0 is None:
                hi, low = ceil, lo
            else:  # torque-speed envelope in the motoring quadrant only (IsaacLab DCMotor's four quadrants)
                hi = np.minimum(ceil, stall * np.maximum(1.0 - dq / w0, 0.0))
                low = -np.minimum(ceil, stall * np.maximum(1.0 + dq / w0, 0.0))
            tau = np.minimum(np.maximum(kp * err - kd * dq, low), hi)
            if gain is not None:
                tau = tau * gain
            for k, j in gear:
                u = cmd[j] - (loop_bias[j] if loop_bias is not None else 0.0)
                g = 1.0 if gain is None else gain[j]
                side = self._motor_side if self._gear[j][0] else self._link_side
                tau[j] = side(k, j, float(u), float(q[j]), float(dq[j]), g)
            if fric is not None:
                tc, ts, ws, dl, bv, s0 = fric
                w = dq[self._fric_idx]
                level = tc + (ts - tc) * np.exp(-np.power(np.abs(w) / ws, dl))
                zmax = level / s0
                self._z = np.clip(self._z + w * dt, -zmax, zmax)
                tau[self._fric_idx] += -s0 * self._z - bv * w
            set_motors(b, idx, pybullet.TORQUE_CONTROL, forces=tau.tolist(), physicsClientId=cid)
            step(physicsClientId=cid)
            if self.keep_trace:
                self.trace.append((tau.copy(), dq))

    def _sensor_noise(self, f: dict[str, np.ndarray]) -> None:
        """Encoder reading and noise (in place): the motor angle and speed where the encoder sits on the
        motor shaft (backlash_link), plus encoder/readout offsets, plus white noise of ``noise`` rad;
        gyro and torso-angle white noise. Draws in the base world's order (q, gyro, angle) from the
        episode's sensor-noise stream."""
        if len(self._read_motor):
            rows = np.searchsorted(self._gear_idx, self._read_motor)
            f["q"][self._read_motor] = self._theta[rows]
            f["dq"][self._read_motor] = self._theta_dot[rows]
        if self._read_bias is not None:
            f["q"] += self._read_bias
        rng = self._noise_rng
        if self.encoder_noise > 0:
            f["q"] += rng.normal(0.0, self.encoder_noise, f["q"].shape)
        if self.gyro_noise > 0:
            f["gyro"] += rng.normal(0.0, self.gyro_noise, 3)
        if self.angle_noise > 0:
            f["angle"] += rng.normal(0.0, self.angle_noise, 2)

    def _info(self, st, fall_reason):
        """The base world's ``info`` plus ``q_link`` (24, true link angles [rad]) and ``q_motor`` (24, motor
        angles [rad] of the gear-play joints, link angles elsewhere): ground truth, never an observation."""
        info = super()._info(st, fall_reason)
        info["q_link"] = st.q.copy()
        qm = st.q.copy()
        if len(self._gear_idx):
            qm[self._gear_idx] = self._theta
        info["q_motor"] = qm
        return info


def make_world(hidden: list[dict], fixed_base: bool = True, noise: float = NOISE, **kwargs) -> StrangerWorld:
    """The strangers' world with ``hidden`` effects, as the blind referee builds its worlds: a hanging
    robot (``fixed_base=True``, excitation in the air) or one standing on the ground (False), encoder
    noise ``noise`` [rad], the torso IMU noises of the blind benchmark with a floating base
    (``benchmarks.blind.families``: gyro 1e-2 rad/s, roll/pitch 2e-3 rad).

    Args:
        hidden: ``[{"family": kind, "targets": [...], "values": [...], "params": [...]}]``, e.g. from
            :func:`.effects.draw_effect`; ``[]`` for none.
        **kwargs: passed to :class:`StrangerWorld` (``robot``, ``imu_noise``, ``physics_dt``, ...).

    Raises:
        ValueError: see :class:`StrangerWorld`.
    """
    return StrangerWorld(hidden, fixed_base=fixed_base, noise=noise, **kwargs)


__all__ = ["KINDS", "StrangerWorld", "make_world"]
