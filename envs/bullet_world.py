"""The "real" world: the same URDF in PyBullet, randomized terrain and the effects of a profile.

Engine set-up (PyBullet Quickstart Guide: ``loadURDF`` flags, ``setJointMotorControl2``,
``createCollisionShape(GEOM_HEIGHTFIELD)``):

* ``loadURDF`` with ``URDF_USE_INERTIA_FROM_FILE`` (else Bullet recomputes inertia from the
  collision shapes); self-collision off (the MuJoCo sim's rule too); link linear/angular damping
  set to 0 (Bullet's defaults are 0.04); Bullet's joint-speed clamp (100 rad/s) lifted, since
  MuJoCo has none: neither engine enforces the URDF velocity limit, the effort limit bounds speed.
* Explicit PD in Python with ``TORQUE_CONTROL`` at every physics step; the default velocity motors
  are disabled (force 0) unless Coulomb friction is drawn, in which case they hold velocity 0
  with that maximum force (bullet3 ``examples/pybullet/examples/jointFrictionAndMotor.py``).
* ``<mimic>`` is ignored by Bullet: both HipYawPitch joints get the same target, and a gear
  constraint (ratio -1: equal angles) couples them like MuJoCo's equality.
* Heightfield, this project's exact recipe (checked in ``tests/test_terrain.py``): heights
  transposed with x reversed, ``numHeightfieldRows = ny``, ``numHeightfieldColumns = nx``, the body
  yawed +90° and lifted to
  ``(min + max) / 2`` -- the same triangles as MuJoCo, to ~1e-8 m.
* The world is rebuilt with ``resetSimulation`` at every reset, so a seed fully determines an
  episode (terrain, effects, sensor noise).
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections import deque

import mujoco
import numpy as np


@contextlib.contextmanager
def _quiet_fd(fd: int):
    """Silence a C-level file descriptor (1: stdout, 2: stderr): Bullet prints ``pybullet build
    time`` (stderr) on import and ``argv[0]=`` (stdout) on connect; the latter would corrupt
    ``--json`` output. Works on the descriptor, so it also holds when ``sys.stdout`` is replaced
    (``contextlib.redirect_stdout``, pytest's capture, a worker forked from such a process)."""
    try:
        os.fstat(fd)
    except OSError:  # no such descriptor: nothing to silence
        yield
        return
    for stream in (sys.stdout, sys.stderr, sys.__stdout__, sys.__stderr__):
        try:
            stream.flush()
        except (AttributeError, OSError, ValueError):
            pass
    saved = os.dup(fd)
    try:
        with open(os.devnull, "w") as devnull:
            os.dup2(devnull.fileno(), fd)
        yield
    finally:
        os.dup2(saved, fd)
        os.close(saved)


with _quiet_fd(2):
    import pybullet
from pybullet_utils.bullet_client import BulletClient

from common.spatial import cross, quat_to_mat
from envs.base import HumanoidEnv, StepState, make_terrain
from envs.effects import EffectDraw, RealProfile, Stochasticity, get_profile
from robots import RobotModel
from terrain import Heightfield, lumpy


def real_ground(seed: int | None, amplitude: float) -> Heightfield | None:
    """The real world's uneven ground of an episode: the lumpy terrain (:func:`terrain.lumpy`, foam
    under turf) of ``amplitude`` [m] drawn from the episode seed's terrain stream (the second of the
    three streams spawned from ``numpy.random.SeedSequence(seed)``: effects, terrain, sensor noise;
    None counts as seed 0), or None (flat) for amplitude 0. :class:`RealWorld` walks this ground;
    another world given it (the identified sim's ``ground``) walks the very same field for the same seed."""
    if amplitude <= 0:
        return None
    terr_ss = np.random.SeedSequence(0 if seed is None else int(seed)).spawn(3)[1]
    return lumpy(np.random.default_rng(terr_ss), amplitude=amplitude)


def _xyzw_to_wxyz(q) -> np.ndarray:
    return np.array([q[3], q[0], q[1], q[2]])


#: Lateral friction of the ground. Bullet combines the two bodies' coefficients by their product
#: (``btManifoldResult::calculateCombinedFriction``: a box with 0.3 on a ground with 0.3 starts to
#: slide at 6 deg, tan = 0.09), so the ground is 1 and a foot's own coefficient is the contact's.
GROUND_FRICTION = 1.0


def add_heightfield(client: BulletClient, terrain: Heightfield, friction: float = GROUND_FRICTION) -> int:
    """Create ``terrain`` in ``client`` as a static body with lateral ``friction``; returns its body id."""
    h = terrain.heights
    ny, nx = h.shape
    c = terrain.cell_size
    lo, hi = float(h.min()), float(h.max())
    data = h[:, ::-1].T.ravel()
    if hi - lo < 1e-9:  # Bullet centres on (min + max) / 2; a constant field is fine
        data = data.copy()
    shape = client.createCollisionShape(pybullet.GEOM_HEIGHTFIELD, meshScale=[c, c, 1.0],
                                        heightfieldData=data.tolist(), numHeightfieldRows=ny,
                                        numHeightfieldColumns=nx)
    body = client.createMultiBody(0, shape, basePosition=[0.0, 0.0, (lo + hi) / 2.0],
                                  baseOrientation=client.getQuaternionFromEuler([0.0, 0.0, np.pi / 2]))
    client.changeDynamics(body, -1, lateralFriction=friction)
    return body


class RealWorld(HumanoidEnv):
    """The PyBullet "real" world.

    Args:
        robot, fixed_base, physics_dt, control_dt, initial_pose, hang_height, max_episode_seconds:
            see :class:`envs.base.HumanoidEnv`.
        profile: effect profile name (``"real"`` default, scaled to the robot's actuators by
            :func:`envs.effects.real_profile_for`; ``"none"``), dict of ranges or
            :class:`envs.effects.RealProfile`.
        terrain: ``"lumpy"`` (default: a fresh lumpy heightfield per episode drawn from the episode
            seed, amplitude from the profile's ``terrain_amplitude``), ``"flat"``/None (plane at 0),
            or a fixed :class:`terrain.Heightfield`. ``reset(options={"terrain": ...})`` overrides it
            for one episode.
        solver_iterations: Bullet's constraint solver iterations.
        ground: ``seed -> Heightfield | None``, the uneven ground of each episode in place of the
            lumpy terrain of ``terrain="lumpy"`` (e.g. the identified sim's Gaussian surface,
            ``sysid.identified.model_ground``: the real world's physics on the sim's ground model).
        stochasticity: the level of per-step randomness (:class:`envs.effects.Stochasticity`: servo
            torque noise per control step, foot friction and contact softness per touchdown); 0, the
            default, draws none.

    Raises:
        ValueError: unknown profile or terrain; a negative stochasticity.
    """

    world = "real"

    def __init__(self, robot: RobotModel | None = None, *, profile="real", terrain="lumpy",
                 solver_iterations: int = 50, ground=None, stochasticity: float = 0.0, **kwargs):
        super().__init__(robot, **kwargs)
        self.ground = ground
        self.stochasticity = Stochasticity(float(stochasticity))
        self.profile: RealProfile = get_profile(profile, self.robot)
        if not (terrain == "lumpy" or terrain is None or terrain == "flat" or isinstance(terrain, Heightfield)):
            raise ValueError(f"terrain must be 'lumpy', 'flat', None or a Heightfield, got {terrain!r}")
        self.terrain_spec = terrain
        self.solver_iterations = int(solver_iterations)
        with _quiet_fd(1):
            self.client = BulletClient(connection_mode=pybullet.DIRECT)
        r = self.robot
        self.effects: EffectDraw = self.profile.draw(np.random.default_rng(0), len(r.joint_names), len(r.links))
        self._fifo: deque = deque()

    def close(self) -> None:
        if getattr(self, "client", None) is not None:
            try:
                self.client.disconnect()
            except pybullet.error:
                pass
            self.client = None

    def __del__(self):  # pragma: no cover - best effort
        self.close()

    # ---------------------------------------------------------------- engine hooks
    def _reset_world(self, seed, options) -> None:
        r, p = self.robot, self.client
        # Independent streams for effects, terrain and sensor noise, all from the episode seed.
        seed = int(seed if seed is not None else self.np_random.integers(2**31))
        # spawn(4)[:3] == spawn(3): the per-step stream leaves the others as they were
        eff_ss, _, noise_ss, step_ss = np.random.SeedSequence(seed).spawn(4)  # the terrain's stream: real_ground
        self.effects = self.profile.draw(np.random.default_rng(eff_ss), len(r.joint_names), len(r.links))
        self._noise_rng = np.random.default_rng(noise_ss)
        if "stochastic_seed" in options:
            step_ss = np.random.SeedSequence(int(options["stochastic_seed"]))
        self._step_rng = np.random.default_rng(step_ss)
        spec = options.get("terrain", self.terrain_spec)
        if spec == "lumpy":
            spec = self.ground(seed) if self.ground is not None else real_ground(seed, self.effects.terrain_amplitude)
        self._terrain = make_terrain(spec)

        p.resetSimulation()
        p.setGravity(0, 0, -9.81)
        p.setPhysicsEngineParameter(fixedTimeStep=self.physics_dt, numSubSteps=0,
                                    numSolverIterations=self.solver_iterations, deterministicOverlappingPairs=1)
        fric = self.effects.foot_friction
        if self._terrain is None:
            plane = p.createCollisionShape(pybullet.GEOM_PLANE)
            ground = p.createMultiBody(0, plane)
            p.changeDynamics(ground, -1, lateralFriction=GROUND_FRICTION)
        else:
            add_heightfield(p, self._terrain)
        flags = pybullet.URDF_USE_INERTIA_FROM_FILE | pybullet.URDF_MAINTAIN_LINK_ORDER
        start = [0.0, 0.0, self.hang_height if self.fixed_base else 1.0]
        self.body = b = p.loadURDF(r.write_urdf(), start, [0, 0, 0, 1], useFixedBase=self.fixed_base, flags=flags)
        names = {p.getJointInfo(b, i)[1].decode(): i for i in range(p.getNumJoints(b))}
        self._jidx = [names[n] for n in r.joint_names]
        link_of = {p.getJointInfo(b, i)[12].decode(): i for i in range(p.getNumJoints(b))}
        link_of[r.root] = -1
        self._link = link_of
        # masses (scaled), no Bullet link damping, feet friction
        links = [-1] + list(range(p.getNumJoints(b)))
        self._masses = np.zeros(len(links))
        for k, li in enumerate(links):
            info = p.getDynamicsInfo(b, li)
            s = float(self.effects.mass_scale[k])
            p.changeDynamics(b, li, linearDamping=0.0, angularDamping=0.0, jointDamping=0.0, maxJointVelocity=1e3)
            if li == -1 and self.fixed_base:
                # Bullet gives a fixed base mass 0, and setting a mass would set it free
                self._masses[k] = r.root_inertial.mass * s
                continue
            p.changeDynamics(b, li, mass=info[0] * s, localInertiaDiagonal=[v * s for v in info[2]])
            self._masses[k] = info[0] * s
        for foot in ("l_sole", "r_sole"):
            p.changeDynamics(b, link_of[r.frames[foot].link], lateralFriction=fric)
        self._links_all = links
        # Bullet's base pose is the pose of the root's *inertial* frame: its centre of mass, rotated onto
        # the principal axes of its inertia (getDynamicsInfo[3], [4]; for the NAO torso roll -19, pitch
        # +23, yaw +74 mrad). The torso (URDF link) frame, which the IMU and every other world read, is
        # that pose times the inverse of the local inertial frame (see _base_link_pose).
        info = p.getDynamicsInfo(b, -1)
        self._com_local_base = np.array(info[3])
        self._base_inertial_conj = np.zeros(4)
        mujoco.mju_negQuat(self._base_inertial_conj, _xyzw_to_wxyz(info[4]))
        # Mimic joints (the NAO's HipYawPitch): a gear constraint keeps both angles equal (MuJoCo's equality).
        for follower, leader in r.mimic.items():
            c = p.createConstraint(b, names[leader], b, names[follower], pybullet.JOINT_GEAR, [1, 0, 0], [0, 0, 0],
                                   [0, 0, 0])
            p.changeConstraint(c, gearRatio=-1.0, maxForce=1000.0)
        # motors: velocity motors only as Coulomb friction, else off
        p.setJointMotorControlArray(b, self._jidx, pybullet.VELOCITY_CONTROL, targetVelocities=[0.0] * len(self._jidx),
                                    forces=self.effects.coulomb_friction_nm.tolist())
        for i, q in zip(self._jidx, self.q0):
            p.resetJointState(b, i, float(q), 0.0)
        if not self.fixed_base:
            soles = [self._frame_world(s)[0] for s in ("l_sole", "r_sole")]
            ground = max(float(self.terrain_height(s[0], s[1])) for s in soles)
            pos, orn = p.getBasePositionAndOrientation(b)
            p.resetBasePositionAndOrientation(b, [pos[0], pos[1], pos[2] + ground - min(s[2] for s in soles) + 0.0005],
                                              orn)
        # effect constants for the PD loop
        e, r = self.effects, self.robot
        self._kp = r.kp * e.kp_scale
        self._kd = r.kd * e.kd_scale
        self._tau_max = r.effort * e.torque_limit_scale
        self._half_play = e.backlash_rad / 2.0
        self._bias = e.encoder_bias_rad
        self._delay = int(round(e.latency_s / self.physics_dt))
        self._fifo = deque([self.q0.copy()] * self._delay)
        self._touching = [False, False]
        self.touchdowns: list[tuple[float, int, dict]] = []  # (time [s], foot 0 left / 1 right, contact drawn)
        if self.stochasticity.active:
            self._touchdown_check()  # the feet's contact at the start: a foot already down draws its own

    def _touchdown_check(self) -> None:
        """Per-step stochasticity: a foot that touched down since the last control step gets a contact
        of its own (:meth:`envs.effects.Stochasticity.touchdown`)."""
        p, b, r = self.client, self.body, self.robot
        for k, foot in enumerate(("l_sole", "r_sole")):
            link = self._link[r.frames[foot].link]
            down = bool(p.getContactPoints(bodyA=b, linkIndexA=link))
            if down and not self._touching[k]:
                c = self.stochasticity.touchdown(self._step_rng, float(self.effects.foot_friction), float(self._masses.sum()))
                p.changeDynamics(b, link, **c)
                self.touchdowns.append((self.time, k, c))
            self._touching[k] = down

    def _base_link_pose(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The root's centre of mass (3,) [m], and the world position (3,) [m] and orientation (w, x, y,
        z) of its URDF link frame, from Bullet's base pose (the pose of the inertial frame; PyBullet
        quickstart guide, ``getBasePositionAndOrientation``) times the inverse local inertial frame."""
        pos, orn = self.client.getBasePositionAndOrientation(self.body)
        quat = np.empty(4)  # q_link = q_inertial * q_local^-1, in double precision (MuJoCo's quaternion ops)
        mujoco.mju_mulQuat(quat, _xyzw_to_wxyz(orn), self._base_inertial_conj)
        com = np.array(pos)
        return com, com - quat_to_mat(quat) @ self._com_local_base, quat

    def _frame_world(self, frame: str) -> tuple[np.ndarray, np.ndarray]:
        """World position (3,) and rotation (3, 3) of a robot frame."""
        fr = self.robot.frames[frame]
        li = self._link[fr.link]
        if li == -1:
            _, origin, quat = self._base_link_pose()
            R = quat_to_mat(quat)
        else:
            ls = self.client.getLinkState(self.body, li, computeForwardKinematics=True)
            origin, R = np.array(ls[4]), quat_to_mat(_xyzw_to_wxyz(ls[5]))
        return origin + R @ np.array(fr.offset), R

    def _advance(self, targets: np.ndarray) -> None:
        # PyBullet's module functions with the client id: the BulletClient wrapper builds a
        # functools.partial per attribute access (1-2 us, ~20 000 calls per episode)
        cid, b, idx = self.client._client, self.body, self._jidx
        get_states, set_motors, step = pybullet.getJointStates, pybullet.setJointMotorControlArray, pybullet.stepSimulation
        fifo, delay = self._fifo, self._delay
        kp, kd, tmax, play, bias = self._kp, self._kd, self._tau_max, self._half_play, self._bias
        lo = -tmax
        kdv = kd + self.effects.viscous_damping
        use_play = bool(np.any(play > 0))
        n = len(idx)
        stochastic = self.stochasticity.active
        if stochastic:  # servo torque noise, one draw per control step
            noise = self.stochasticity.torque_noise(self._step_rng, tmax)
        for _ in range(self.n_substeps):
            if delay:
                fifo.append(targets)
                cmd = fifo.popleft()
            else:
                cmd = targets
            js = get_states(b, idx, physicsClientId=cid)
            q = np.fromiter((s[0] for s in js), float, n)
            dq = np.fromiter((s[1] for s in js), float, n)
            err = cmd - (q + bias)
            if use_play:
                err = np.sign(err) * np.maximum(np.abs(err) - play, 0.0)
            tau = kp * err - kdv * dq
            if stochastic:
                tau = tau + noise
            tau = np.minimum(np.maximum(tau, lo), tmax)  # np.clip without its wrapper
            set_motors(b, idx, pybullet.TORQUE_CONTROL, forces=tau.tolist(), physicsClientId=cid)
            step(physicsClientId=cid)
        if stochastic:
            self._touchdown_check()

    def _state(self) -> StepState:
        p, b = self.client, self.body
        js = p.getJointStates(b, self._jidx)
        q = np.array([s[0] for s in js])
        dq = np.array([s[1] for s in js])
        com_world, origin, quat = self._base_link_pose()
        v_com, w = (np.array(v) for v in p.getBaseVelocity(b))
        R = quat_to_mat(quat)
        linvel = v_com + cross(w, origin - com_world)
        acc_pt = origin + R @ self._accel_offset
        accel_vel = v_com + cross(w, acc_pt - com_world)
        force = np.zeros(2)
        cop = np.zeros((2, 3))
        for k, foot in enumerate(("l_sole", "r_sole")):
            for c in p.getContactPoints(bodyA=b, linkIndexA=self._link[self.robot.frames[foot].link]):
                fn = c[9]
                force[k] += fn
                cop[k] += fn * np.array(c[5])  # contact position on the robot
        with np.errstate(invalid="ignore", divide="ignore"):
            cop = np.where(force[:, None] > 0, cop / force[:, None], np.nan)
        return StepState(q, dq, origin, quat, linvel, w, accel_vel, force, cop)

    def _com(self) -> np.ndarray:
        p, b = self.client, self.body
        pos = [p.getBasePositionAndOrientation(b)[0]]
        pos += [s[0] for s in p.getLinkStates(b, self._links_all[1:])]
        return (self._masses[:, None] * np.array(pos)).sum(0) / self._masses.sum()

    def _to_sole(self, sole: str, p_world: np.ndarray) -> np.ndarray:
        o, R = self._frame_world(sole)
        return R.T @ (p_world - o)

    def _sensor_noise(self, f: dict[str, np.ndarray]) -> None:
        e, rng = self.effects, self._noise_rng
        f["q"] += e.encoder_bias_rad
        if e.encoder_noise_rad > 0:
            f["q"] += rng.normal(0.0, e.encoder_noise_rad, f["q"].shape)
        f["gyro"] += e.gyro_bias
        if e.gyro_noise > 0:
            f["gyro"] += rng.normal(0.0, e.gyro_noise, 3)
        if e.accel_noise > 0:
            f["acc"] += rng.normal(0.0, e.accel_noise, 3)
        if e.angle_noise_rad > 0:
            f["angle"] += rng.normal(0.0, e.angle_noise_rad, 2)


#: The name of this class when the project modelled the NAO only (kept for user code that uses it).
NaoRealEnv = RealWorld
