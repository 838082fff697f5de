"""The referee's worlds: hidden effects injected with the referee's own code, not ``sysid/``'s models.

* ``sim`` (sim-as-real, :class:`RefereeSimWorld`): MuJoCo with the PD law computed in Python and
  applied as motor torque at each 1 ms step; latency as a command FIFO with ±1 ms jitter per control
  step (the candidate is MuJoCo's interpolated ``actuator_delay``), backlash as a dead band on the PD
  error (the candidate is a series play hinge), viscous damping inside the clipped PD torque (the
  candidate is ``dof_damping``), kp and torque limit in the Python PD, Coulomb friction as MuJoCo
  ``frictionloss`` with hard stiction (2 ms constraint time constant), link mass / armature as model
  edits, sensor bias as an offset on the logged angle, joint compliance as a massless motor behind a
  spring (:class:`_SeriesSpring`, backward Euler; the candidate is a MuJoCo series hinge with joint
  stiffness and a light motor body), a parallel spring as the robot joint's own MuJoCo ``stiffness``
  about the zero angle (outside the referee's clipped PD).
* ``real`` (:class:`RefereeRealWorld`): the PyBullet world of ``envs/bullet_world.py`` (its own
  effect code: explicit PD, velocity-motor Coulomb friction, dead-band backlash, mass scaling), plus
  a referee FIFO with jitter for latency, a logged-angle offset for sensor bias and the same
  massless-motor spring for joint compliance, and a parallel spring as an extra torque -k q added to
  the clipped PD torque at every physics step (PyBullet has no joint stiffness). PyBullet has no
  armature, so the ``armature`` class is run in the sim world only.

:func:`make_world` builds either from a list of hidden effects (:func:`.referee.draw_effect`).
"""

from __future__ import annotations

import collections

import numpy as np

from envs.bullet_world import NaoRealEnv
from envs.mujoco_world import NaoSimEnv
from robots import nao_h25

from .families import ANGLE_NOISE, GYRO_NOISE, NOISE


def _arrays(effects: list[dict], robot) -> dict:
    """Referee arrays per joint (24) / link (25) from hidden effects."""
    nj, links = len(robot.joint_names), list(robot.links)
    jidx = {n: i for i, n in enumerate(robot.joint_names)}
    a = {"kp_scale": np.ones(nj), "kd_scale": np.ones(nj), "backlash": np.zeros(nj), "coulomb": np.zeros(nj), "damping": np.zeros(nj),
         "armature": np.zeros(nj), "bias": np.zeros(nj), "compliance": np.zeros(nj), "parallel": np.zeros(nj),
         "mass_scale": np.ones(len(links)), "latency": 0.0,
         "torque_scale": 1.0, "foot_friction": None, "ground_timeconst": None}
    for e in effects:
        for tg, v in zip(e["targets"], e["values"]):
            f = e["family"]
            if f == "latency":
                a["latency"] = v
            elif f == "foot_friction":
                a["foot_friction"] = v
            elif f == "ground_compliance":
                a["ground_timeconst"] = v
            elif f == "terrain_roughness":
                pass  # the ground itself: see record()
            elif f == "torque_limit":
                a["torque_scale"] = v
            elif f == "link_mass":
                a["mass_scale"][links.index(tg)] = v
            elif f == "torque_constant":  # the servo's torque per unit of PD output: kp and kd together
                a["kp_scale"][jidx[tg]] *= v
                a["kd_scale"][jidx[tg]] *= v
            else:
                key = {"pd_gain": "kp_scale", "backlash": "backlash", "coulomb_friction": "coulomb",
                       "viscous_damping": "damping", "armature": "armature", "sensor_bias": "bias",
                       "joint_compliance": "compliance", "parallel_spring": "parallel"}[f]
                if key == "kp_scale":
                    a[key][jidx[tg]] *= v  # composes with a torque-constant error on the same joint
                else:
                    a[key][jidx[tg]] = v
    return a


# ------------------------------------------------------------------------------------------ worlds
class _Fifo:
    """Command FIFO at the physics rate with a per-control-step jitter of ±1 physics step."""

    def __init__(self, delay_steps: int, q0: np.ndarray, rng: np.random.Generator):
        self.n = int(delay_steps)
        self.hist = collections.deque([q0.copy()] * (self.n + 2), maxlen=self.n + 3)
        self.rng = rng
        self.d = self.n

    def new_control_step(self) -> None:
        self.d = self.n + int(self.rng.integers(-1, 2)) if self.n >= 2 else self.n

    def push_pop(self, targets: np.ndarray) -> np.ndarray:
        self.hist.append(targets)
        return self.hist[-1 - self.d] if self.d > 0 else targets


class _SeriesSpring:
    """Referee joint compliance: a massless motor behind a spring k = 1/c on the joints with c > 0.

    The servo's PD acts on the motor angle th: clip(kp (u - th) - kd th', +-effort) = k (th - q) (no
    motor inertia), integrated by backward Euler at the physics step (stable for any k); the link
    gets k (th - q).
    (The tool's candidate is a MuJoCo series hinge with joint stiffness and a light motor body.)
    """

    def __init__(self, compliance: np.ndarray, kp: np.ndarray, kd: np.ndarray, dt: float):
        self.mask = np.asarray(compliance) > 0
        self.k = 1.0 / np.asarray(compliance)[self.mask]
        self.kp, self.kd, self.dt = kp[self.mask], kd[self.mask], dt
        self.th = None

    def __bool__(self) -> bool:
        return bool(self.mask.any())

    def reset(self, q: np.ndarray) -> None:
        self.th = np.asarray(q, dtype=float)[self.mask].copy()

    def link_torque(self, cmd: np.ndarray, q: np.ndarray, tmax: np.ndarray) -> np.ndarray:
        """Spring torque on the links of the masked joints after one step toward ``cmd``. The motor
        torque (= the spring torque, the motor being massless) is limited to ``tmax``; a limited
        motor sits where the spring carries exactly that torque."""
        qm, c, tm = q[self.mask], cmd[self.mask], tmax[self.mask]
        a = self.kd / self.dt
        th = (a * self.th + self.kp * c + self.k * qm) / (a + self.kp + self.k)
        tau = np.clip(self.k * (th - qm), -tm, tm)
        self.th = qm + tau / self.k
        return tau


class RefereeSimWorld(NaoSimEnv):
    """Sim-as-real: MuJoCo with the referee's own PD loop and effects (see module docstring)."""

    world = "real"

    def __init__(self, hidden: list[dict], noise: float = NOISE, **kw):
        self.hidden = hidden
        self.noise = noise
        super().__init__(fixed_base=kw.pop("fixed_base", True), **kw)

    def _build(self) -> None:
        super()._build()
        import mujoco

        r, m = self.robot, self.model
        a = _arrays(self.hidden, r)
        self.arr = a
        m.actuator_gainprm[:, 0] = 1.0
        m.actuator_biasprm[:, :3] = 0.0
        m.actuator_forcerange[:] = [-1e3, 1e3]
        for k, ln in enumerate(r.links):
            b = m.body(ln).id
            m.body_mass[b] *= a["mass_scale"][k]
            m.body_inertia[b] *= a["mass_scale"][k]
        m.dof_armature[self._dadr] += a["armature"]
        m.dof_frictionloss[self._dadr] = a["coulomb"]
        # parallel spring: the passive -k q of each robot hinge about its zero angle (MuJoCo joint
        # stiffness, -stiffness (q - qpos_spring); the plain sim has neither)
        jnt = m.dof_jntid[self._dadr]
        if np.any(m.jnt_stiffness[jnt] != 0):
            raise ValueError("the referee's sim world expects joints without stiffness")
        m.jnt_stiffness[jnt] = a["parallel"]
        m.qpos_spring[self._qadr] = 0.0
        m.dof_solref[self._dadr, 0] = 2 * self.physics_dt  # hard stiction, like PyBullet's motor friction
        if a["foot_friction"] is not None:
            m.geom_friction[:, 0] = a["foot_friction"]
        if a["ground_timeconst"] is not None:
            m.geom_solref[:, 0] = a["ground_timeconst"]
        mujoco.mj_setConst(m, self.data)
        self._kp = r.kp * a["kp_scale"]
        self._kd = r.kd * a["kd_scale"] + a["damping"]
        self._tmax = r.effort * a["torque_scale"]
        self._play = a["backlash"] / 2.0
        self._spring = _SeriesSpring(a["compliance"], self._kp, r.kd, self.physics_dt)

    def _reset_world(self, seed, options) -> None:
        super()._reset_world(seed, options)
        self._spring.reset(self.data.qpos[self._qadr])
        ss = np.random.SeedSequence(seed if seed is not None else 0).spawn(2)
        self._noise_rng = np.random.default_rng(ss[0])
        self._fifo = _Fifo(round(self.arr["latency"] / self.physics_dt), self.q0, np.random.default_rng(ss[1]))

    def _advance(self, targets: np.ndarray) -> None:
        import mujoco

        m, d = self.model, self.data
        self._fifo.new_control_step()
        use_play = bool(np.any(self._play > 0))
        for _ in range(self.n_substeps):
            cmd = self._fifo.push_pop(targets)
            q, dq = d.qpos[self._qadr], d.qvel[self._dadr]
            err = cmd - q
            if use_play:
                err = np.sign(err) * np.maximum(np.abs(err) - self._play, 0.0)
            tau = self._kp * err - self._kd * dq
            if self._spring:
                sp = self._spring
                tau[sp.mask] = sp.link_torque(cmd, q, self._tmax) - self.arr["damping"][sp.mask] * dq[sp.mask]
            d.ctrl[:] = np.clip(tau, -self._tmax, self._tmax)
            mujoco.mj_step(m, d)

    def _sensor_noise(self, f) -> None:
        f["q"] += self.arr["bias"] + self._noise_rng.normal(0.0, self.noise, f["q"].shape)
        if not self.fixed_base:
            f["angle"] += self._noise_rng.normal(0.0, ANGLE_NOISE, 2)
            f["gyro"] += self._noise_rng.normal(0.0, GYRO_NOISE, 3)


class RefereeRealWorld(NaoRealEnv):
    """PyBullet real world with the hidden effects (FIFO-with-jitter latency, logged-angle bias)."""

    def __init__(self, hidden: list[dict], noise: float = NOISE, **kw):
        from sysid.worlds import FrozenProfile, identity_draw

        r = nao_h25()
        self.arr = a = _arrays(hidden, r)
        draw = identity_draw(r, "referee", kp_scale=a["kp_scale"], kd_scale=a["kd_scale"], backlash_rad=a["backlash"],
                             coulomb_friction_nm=a["coulomb"], viscous_damping=a["damping"],
                             torque_limit_scale=a["torque_scale"], mass_scale=a["mass_scale"],
                             encoder_noise_rad=noise, angle_noise_rad=ANGLE_NOISE, gyro_noise=GYRO_NOISE,
                             **({"foot_friction": a["foot_friction"]} if a["foot_friction"] is not None else {}))
        super().__init__(r, profile=FrozenProfile(name="referee", frozen=draw), terrain="flat",
                         fixed_base=kw.pop("fixed_base", True), **kw)

    def _reset_world(self, seed, options) -> None:
        super()._reset_world(seed, options)
        self._jfifo = _Fifo(round(self.arr["latency"] / self.physics_dt), self.q0,
                            np.random.default_rng(np.random.SeedSequence(seed or 0).spawn(4)[3]))
        self._spring = _SeriesSpring(self.arr["compliance"], self._kp, self.robot.kd, self.physics_dt)
        self._spring.reset(np.array([s[0] for s in self.client.getJointStates(self.body, self._jidx)]))

    def _advance(self, targets: np.ndarray) -> None:
        import pybullet

        par = self.arr["parallel"]
        if self.arr["latency"] <= 0 and not self._spring and not np.any(par):
            return super()._advance(targets)
        p, b, idx = self.client, self.body, self._jidx
        kp, kd, tmax, play = self._kp, self._kd, self._tau_max, self._half_play
        visc = self.effects.viscous_damping
        use_play = bool(np.any(play > 0))
        self._jfifo.new_control_step()
        sp = self._spring
        for _ in range(self.n_substeps):
            cmd = self._jfifo.push_pop(targets)
            js = p.getJointStates(b, idx)
            q = np.fromiter((s[0] for s in js), float, len(idx))
            dq = np.fromiter((s[1] for s in js), float, len(idx))
            err = cmd - q
            if use_play:
                err = np.sign(err) * np.maximum(np.abs(err) - play, 0.0)
            tau = kp * err - (kd + visc) * dq
            if sp:
                tau[sp.mask] = sp.link_torque(cmd, q, tmax) - visc[sp.mask] * dq[sp.mask]
            tau = np.clip(tau, -tmax, tmax) - par * q  # a parallel spring is passive: outside the motor's limit
            p.setJointMotorControlArray(b, idx, pybullet.TORQUE_CONTROL, forces=tau.tolist())
            p.stepSimulation()

    def _sensor_noise(self, f) -> None:
        super()._sensor_noise(f)
        f["q"] += self.arr["bias"]



def make_world(world: str, hidden: list[dict], fixed_base: bool = True, noise: float = NOISE):
    """The referee world ``world`` ("sim", "real" or "strangers": ``benchmarks.strangers.world``, effect
    models written apart from this package's, used through its API only) with the ``hidden`` effects
    injected and ``noise`` [rad] of encoder noise.

    Raises:
        ValueError: an unknown world.
    """
    if world == "sim":
        return RefereeSimWorld(hidden, noise=noise, fixed_base=fixed_base)
    if world == "real":
        return RefereeRealWorld(hidden, noise=noise, fixed_base=fixed_base)
    if world == "strangers":
        from benchmarks.strangers.world import make_world as strangers_world

        return strangers_world(hidden, fixed_base=fixed_base, noise=noise)
    raise ValueError(f"unknown referee world {world!r}; known: sim, real, strangers")
