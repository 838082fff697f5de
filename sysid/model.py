"""Replay models: the MuJoCo sim of ``envs.mujoco_world`` plus the structure the candidate effects need.

:func:`base_spec` rebuilds exactly the model of :func:`envs.mujoco_world.build_model` as an
``MjSpec`` (a test checks the compiled fields agree), so that candidates can change structure and
the identified model can be exported as MJCF (``MjSpec.to_xml``). On top of the sim it adds:

* actuator history buffers (``nsample``, ``interp="linear"``) on every actuator, so actuation
  latency is a run-time field (``MjModel.actuator_delay``) and every candidate model has the same
  sizes (``mujoco.rollout.rollout`` batches a list of models only when their sizes agree: MuJoCo
  documentation, Python bindings, "rollout");
* a stiff dry-friction constraint (``solref_friction``, 2 physics steps) on every joint, used
  only when a Coulomb candidate sets ``dof_frictionloss``;
* ``jointpos`` sensors for the robot's n hinges (and the series play hinges), plus a torso
  ``framequat`` and ``gyro`` for floating-base replays, so :func:`mujoco.rollout.rollout` returns
  only what is compared with the recording;
* optionally, for gear backlash, a second "play" hinge in series with a robot joint on the same
  body (same axis and anchor) with range ``+-gap/2`` and a stiff limit; the motor hinge gets a
  small armature (else the two-hinge inertia matrix is singular) and 10 % of its PD damping as
  ``dof_damping`` (implicit under Euler, so the light motor side stays stable at 1 ms). The
  measured angle is the sum of both hinges (MuJoCo docs, Modeling -> Backlash). 90 % of the
  servo damping acts on the output angle through a fixed tendon (motor + play), like a dead-band
  servo whose damping sees the output velocity;
* optionally, for joint compliance, a "spring" hinge in series with a robot joint (same axis and
  anchor) whose joint ``stiffness`` is the series spring 1/c (flexible-joint model, Spong 1987:
  the servo closes its PD loop, damping included and clipped to the effort, on the motor angle;
  the encoder reads the output = motor + spring). The motor hinge gets a small armature
  (:func:`spring_motor_armature`). The spring force is explicit under Euler, so each joint has a
  stiffest spring the 1 ms step integrates stably (:func:`spring_stiffness_max`). A joint may
  have both a play and a spring hinge (motor -> play -> spring; the servo acts on the motor).

A :class:`Structure` names one such layout; a :class:`ReplayModel` is its compiled model with the
index maps replays and candidates use.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import mujoco
import numpy as np

from common.defaults import PHYSICS_DT
from common.spatial import quat_to_mat
from envs.effects import NOMINAL_FOOT_FRICTION
from envs.mujoco_world import build_spec
from robots import RobotModel, get_robot
from terrain import Heightfield

#: Longest actuation latency a candidate can take [s] (history buffer length).
DELAY_MAX = 0.08
#: Armature of the motor side of a backlash pair [kg m^2]: small against the link inertias
#: (AnkleRoll ~1.8e-4) but >= kp dt^2 so the explicit PD stays stable at 1 ms.
PLAY_MOTOR_ARMATURE = 5e-5
_PLAY_SUFFIX = "__play"
#: Smallest armature of the motor side of a series-spring pair [kg m^2] (a positive value keeps
#: the motor + spring inertia matrix regular).
SPRING_MOTOR_ARMATURE_MIN = 1e-6


def spring_motor_armature(kp: float, kd: float, physics_dt: float) -> float:
    """Armature [kg m^2] of the motor side of a series-spring pair: as light as the Euler step allows
    (a servo's motor side is light against its link), with the explicit servo damping and a spring
    up to 5 kp stable with a factor 2 margin: ``kd dt / I_m <= 1`` and ``dt^2 (kp + k) / I_m <= 1``,
    i.e. ``max(kd dt, 6 kp dt^2)`` (1.3e-5 for WristYaw, 1.8e-4 for AnkleRoll at 1 ms)."""
    return max(SPRING_MOTOR_ARMATURE_MIN, kd * physics_dt, 6.0 * kp * physics_dt ** 2)


_SPRING_SUFFIX = "__spring"
#: Name suffix of the actuator that makes a joint's dry friction a Stribeck friction: a velocity feedback
#: force ``clip(k qdot, +-delta)`` beside a frictionloss raised by ``delta`` (see :func:`replay_spec`).
STRIBECK_SUFFIX = "__stribeck"
#: Stribeck velocity [rad/s] of the Stribeck friction candidate: the speed over which the static excess
#: has fallen away. BAM's fitted Stribeck velocities of small geared servos are 0.05-0.3 rad/s
#: (Duclusaud et al., arXiv:2410.08650, Table II); 0.1 rad/s is this library's choice.
STRIBECK_VELOCITY = 0.1
#: Time constant [s] of the command filter every replay actuator has (``dyntype`` filterexact with
#: ``actearly``: the force uses the filtered command of the same step): this small it passes the
#: command through unchanged (1 - exp(-dt / tau) = 1 at any physics step of 1e-4 s or more); the
#: ``command_lowpass`` candidate raises it.
LOWPASS_MIN = 1e-6
#: Share of a joint's effective inertia the Stribeck element's velocity gain k may reach per physics step
#: (``k dt / I_eff <= 0.5``): the element is an explicit negative damping below the Stribeck velocity.
STRIBECK_GAIN_SHARE = 0.5
#: Time constant of the dry-friction constraint in physics steps: MuJoCo's default (20 ms) lets a
#: joint creep under a load below the friction torque; geared servos (and PyBullet's velocity-motor
#: friction) stick hard, which 2 steps reproduces (measured: PyBullet knee friction 0.2 N m is
#: matched to 0.8 mrad RMS instead of 2.5).
FRICTION_TIMECONST_STEPS = 2


@dataclass(frozen=True)
class Structure:
    """A replay model layout.

    Attributes:
        fixed_base: torso welded at ``hang_height`` (True) or on a free joint.
        physics_dt: physics step [s] (the recording's ``physics_dt``; default 1 ms).
        play_joints: robot joints that get a series backlash hinge.
        spring_joints: robot joints that get a series compliance (spring) hinge.
        stribeck_joints: robot joints that get a Stribeck friction element (an extra actuator,
            :data:`STRIBECK_SUFFIX`).
        command_filter: every actuator has a first-order command filter (:data:`LOWPASS_MIN`, the
            ``command_lowpass`` candidate's handle); False: the plain sim's actuators (no activation
            state), for a world without that term that must step like the sim bit for bit.
        friction: sliding friction of all contacts (foot friction candidate edits the field).
        hang_height: root height of a fixed-base model [m]; None: the robot's
            ``RobotModel.hang_height`` (where the worlds hang it; 0.6 m for the NAO).
        terrain: the ground is a :data:`TERRAIN_SIZE` heightfield (``ground_hfield``) whose
            heights a caller writes with :func:`set_terrain` (uneven-ground simulations of
            :mod:`sysid.roughness`) instead of a plane.
        robot: the robot's name (``RobotModel.name``: ``"nao"``, ``"g1"``, ``"talos"``; a
            recording's ``meta["robot"]``); :func:`replay_model` builds that robot.
    """

    fixed_base: bool = True
    physics_dt: float = PHYSICS_DT
    play_joints: tuple[str, ...] = ()
    friction: float = NOMINAL_FOOT_FRICTION
    hang_height: float | None = None
    terrain: bool = False
    spring_joints: tuple[str, ...] = ()
    robot: str = "nao"
    stribeck_joints: tuple[str, ...] = ()
    command_filter: bool = True

    @property
    def n_series(self) -> int:
        """Number of extra series hinges."""
        return len(self.play_joints) + len(self.spring_joints)

    @property
    def size_key(self) -> tuple[int, int]:
        """(extra series hinges, extra Stribeck actuators): models with the same key have the same sizes
        and batch together in one ``mujoco.rollout`` call."""
        return self.n_series, len(self.stribeck_joints)


#: Heightfield of a ``terrain`` structure: (half x, half y) [m], cell [m], elevation range [m]
#: (heights within +-range/2 of z = 0 are representable; the field is flat at z = 0 until set).
TERRAIN_SIZE = (1.0, 1.0)
TERRAIN_CELL = 0.04
TERRAIN_RANGE = 0.1
#: (ny, nx) grid nodes of that heightfield.
TERRAIN_SHAPE = (int(round(2 * TERRAIN_SIZE[1] / TERRAIN_CELL)) + 1, int(round(2 * TERRAIN_SIZE[0] / TERRAIN_CELL)) + 1)


def base_spec(robot: RobotModel, *, fixed_base: bool, physics_dt: float, hang_height: float = 0.6,
              friction: float = NOMINAL_FOOT_FRICTION, terrain: Heightfield | None = None) -> mujoco.MjSpec:
    """The ``MjSpec`` of :func:`envs.mujoco_world.build_model` (same steps, same order) on flat ground,
    or on the heightfield ``terrain``.

    Returns:
        An uncompiled spec: the robot's n hinges (+ free joint ``root`` unless ``fixed_base``), n PD
        actuators named like the joints, sites for ``robot.frames``, a ground plane ``ground``.
    """
    return build_spec(robot, terrain, fixed_base=fixed_base, hang_height=hang_height, physics_dt=physics_dt,
                      friction=friction)


def replay_spec(robot: RobotModel, structure: Structure, ground: Heightfield | None = None) -> mujoco.MjSpec:
    """:func:`base_spec` plus history buffers, sensors and the structure's play hinges; ``ground``: a
    fixed heightfield (the walking terrain of :class:`sysid.identified.IdentifiedSimEnv`) instead of
    the plane (not with a ``terrain`` structure, whose field is written at run time).

    Raises:
        ValueError: both a ``terrain`` structure and a ``ground``.
    """
    s = structure
    if s.terrain and ground is not None:
        raise ValueError("a terrain structure writes its own heightfield: give no fixed ground")
    hang = robot.hang_height if s.hang_height is None else s.hang_height
    spec = base_spec(robot, fixed_base=s.fixed_base, physics_dt=s.physics_dt, hang_height=hang,
                     friction=s.friction, terrain=ground)
    if s.terrain:  # swap the plane for a heightfield with a fixed elevation range (data set at run time)
        ground = spec.geom("ground")
        ny, nx = TERRAIN_SHAPE
        hf = spec.add_hfield(name="ground_hfield", nrow=ny, ncol=nx)
        hf.size = [TERRAIN_SIZE[0], TERRAIN_SIZE[1], TERRAIN_RANGE, 0.05]
        hf.userdata = [0.0] * (nx * ny)  # heights written after compiling (set_terrain)
        ground.type = mujoco.mjtGeom.mjGEOM_HFIELD
        ground.hfieldname = "ground_hfield"
        ground.pos = [0.0, 0.0, -TERRAIN_RANGE / 2]
    nsample = int(np.ceil(DELAY_MAX / s.physics_dt)) + 2
    for j in spec.joints:  # hard stiction for the Coulomb candidate (inactive while frictionloss = 0)
        j.solref_friction = [FRICTION_TIMECONST_STEPS * s.physics_dt, 1.0]
    for a in spec.actuators:
        a.nsample = nsample
        a.interp = 1  # linear
        a.delay = 0.0
        if s.command_filter:  # a first-order command filter, a pass-through until a candidate sets it
            a.dyntype = mujoco.mjtDyn.mjDYN_FILTEREXACT
            a.dynprm[0] = LOWPASS_MIN
            a.actearly = True
    kd = dict(zip(robot.joint_names, robot.kd))
    for name in s.play_joints:
        if name not in kd:
            raise KeyError(f"unknown joint {name!r} for a backlash hinge")
        motor = spec.joint(name)
        body = motor.parent
        play = body.add_joint(name=name + _PLAY_SUFFIX, type=mujoco.mjtJoint.mjJNT_HINGE,
                              axis=list(motor.axis), pos=list(motor.pos))
        play.limited = mujoco.mjtLimited.mjLIMITED_TRUE
        play.range = [-1e-4, 1e-4]
        play.solref_limit = [2 * s.physics_dt, 1.0]
        play.solimp_limit = [0.99, 0.999, 0.001, 0.5, 2.0]
        # servo damping: 10 % on the light motor side (implicit dof damping, keeps the motor from
        # ringing inside the gap), 90 % on the output angle (motor + play) through a fixed tendon,
        # so the engaged joint has the nominal damping and a free-floating output is still damped
        # (the dead-band servo form: tau = kp dz(q* - q) - kd qdot acts on the output)
        motor.armature = PLAY_MOTOR_ARMATURE
        motor.damping = [0.1 * float(kd[name]), 0.0, 0.0]
        spec.actuator(name).biasprm[2] = 0.0
        if name in s.spring_joints:  # play and spring in series: the servo (set below) drives the motor,
            play.armature = PLAY_MOTOR_ARMATURE  # a gear stage between them (else M is singular)
            continue
        ten = spec.add_tendon(name=name + "__out")
        ten.wrap_joint(name, 1.0)
        ten.wrap_joint(name + _PLAY_SUFFIX, 1.0)
        ten.damping = [0.9 * float(kd[name]), 0.0, 0.0]
    for name in s.spring_joints:
        if name not in kd:
            raise KeyError(f"unknown joint {name!r} for a series spring")
        motor = spec.joint(name)
        spring = motor.parent.add_joint(name=name + _SPRING_SUFFIX, type=mujoco.mjtJoint.mjJNT_HINGE,
                                        axis=list(motor.axis), pos=list(motor.pos))
        spring.stiffness = [1e3, 0.0, 0.0]  # placeholder: the candidate writes jnt_stiffness = 1 / compliance
        # the servo's PD, damping included, acts on the motor angle through the actuator (clipped
        # to the effort like the sim's servo); the motor armature keeps that explicit PD stable
        motor.armature = spring_motor_armature(float(robot.kp[robot.joint_index([name])[0]]),
                                               float(kd[name]), s.physics_dt)
        motor.damping = [0.0, 0.0, 0.0]
        spec.actuator(name).biasprm[2] = -float(kd[name])
    for name in s.stribeck_joints:
        if name not in kd:
            raise KeyError(f"unknown joint {name!r} for a Stribeck friction element")
        # Stribeck friction (static level tau_c + delta falling to tau_c above the Stribeck velocity):
        # the joint's frictionloss carries tau_c + delta (stiction, implicit constraint) and this
        # actuator gives back up to delta as the joint speeds up, force clip(k qdot, +-delta), a
        # piecewise-linear Stribeck curve (Armstrong-Helouvry et al., Automatica 30(7), 1994). Gain 0: the
        # control has no effect; the candidate writes k (biasprm[2]) and delta (forcerange).
        a = spec.add_actuator(name=name + STRIBECK_SUFFIX, target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        a.gaintype = mujoco.mjtGain.mjGAIN_FIXED
        a.gainprm[0] = 0.0
        a.biastype = mujoco.mjtBias.mjBIAS_AFFINE
        a.biasprm[0:3] = [0.0, 0.0, 0.0]
        a.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        a.forcerange = [-1e-9, 1e-9]
        a.ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE
    for name in robot.joint_names:
        spec.add_sensor(name=f"q:{name}", type=mujoco.mjtSensor.mjSENS_JOINTPOS, objtype=mujoco.mjtObj.mjOBJ_JOINT,
                        objname=name)
    for name in s.play_joints:
        spec.add_sensor(name=f"play:{name}", type=mujoco.mjtSensor.mjSENS_JOINTPOS,
                        objtype=mujoco.mjtObj.mjOBJ_JOINT, objname=name + _PLAY_SUFFIX)
    for name in s.spring_joints:
        spec.add_sensor(name=f"spring:{name}", type=mujoco.mjtSensor.mjSENS_JOINTPOS,
                        objtype=mujoco.mjtObj.mjOBJ_JOINT, objname=name + _SPRING_SUFFIX)
    if not s.fixed_base:
        spec.add_sensor(name="torso_quat", type=mujoco.mjtSensor.mjSENS_FRAMEQUAT, objtype=mujoco.mjtObj.mjOBJ_XBODY,
                        objname=robot.root)
        spec.add_sensor(name="gyro", type=mujoco.mjtSensor.mjSENS_GYRO, objtype=mujoco.mjtObj.mjOBJ_SITE,
                        objname="gyro")
    return spec


class ReplayModel:
    """A compiled replay model and its index maps.

    Attributes:
        robot, structure, spec, model (template ``MjModel``; copy before editing).
        qadr, dadr: (n,) qpos / dof address of each of the robot's n joints' (motor) hinge.
        play_qadr, play_dadr, play_jnt: dict joint name -> address / joint id of its play hinge.
        play_tendon: dict joint name -> id of the fixed tendon (motor + play: the output angle) that
            carries 90 % of the servo damping of a play joint without a series spring.
        stribeck_act: dict joint name -> actuator id of its Stribeck friction element.
        spring_qadr, spring_dadr, spring_jnt: the same for series-spring hinges.
        act: (n,) actuator id per robot joint.  body: dict link name -> body id.
        meas: (n, nsensordata) matrix mapping sensor data to the n measured joint angles.
        quat_adr, gyro_adr: sensordata addresses of the torso quaternion (4) and gyro (3), or None.
        nsample: history samples per actuator.
    """

    def __init__(self, robot: RobotModel, structure: Structure, ground: Heightfield | None = None):
        self.robot, self.structure = robot, structure
        self.spec = replay_spec(robot, structure, ground)
        self.model = self.spec.compile()
        m = self.model
        if structure.terrain:  # MuJoCo normalises a constant userdata to 0: set the flat field at z = 0
            set_terrain(m, np.zeros(TERRAIN_SHAPE))
        jid = [m.joint(n).id for n in robot.joint_names]
        self.qadr = np.array([m.jnt_qposadr[j] for j in jid])
        self.dadr = np.array([m.jnt_dofadr[j] for j in jid])
        self.play_jnt = {n: m.joint(n + _PLAY_SUFFIX).id for n in structure.play_joints}
        self.play_qadr = {n: int(m.jnt_qposadr[j]) for n, j in self.play_jnt.items()}
        self.play_dadr = {n: int(m.jnt_dofadr[j]) for n, j in self.play_jnt.items()}
        self.play_tendon = {n: m.tendon(n + "__out").id for n in structure.play_joints
                            if n not in structure.spring_joints}
        self.stribeck_act = {n: m.actuator(n + STRIBECK_SUFFIX).id for n in structure.stribeck_joints}
        self.spring_jnt = {n: m.joint(n + _SPRING_SUFFIX).id for n in structure.spring_joints}
        self.spring_qadr = {n: int(m.jnt_qposadr[j]) for n, j in self.spring_jnt.items()}
        self.spring_dadr = {n: int(m.jnt_dofadr[j]) for n, j in self.spring_jnt.items()}
        self.act = np.array([m.actuator(n).id for n in robot.joint_names])
        self.body = {name: m.body(name).id for name in robot.links}
        self.meas = np.zeros((len(robot.joint_names), m.nsensordata))
        for i, n in enumerate(robot.joint_names):
            self.meas[i, m.sensor_adr[m.sensor(f"q:{n}").id]] = 1.0
            if n in structure.play_joints:
                self.meas[i, m.sensor_adr[m.sensor(f"play:{n}").id]] = 1.0
            if n in structure.spring_joints:
                self.meas[i, m.sensor_adr[m.sensor(f"spring:{n}").id]] = 1.0
        self.quat_adr = self.gyro_adr = None
        if not structure.fixed_base:
            self.quat_adr = int(m.sensor_adr[m.sensor("torso_quat").id])
            self.gyro_adr = int(m.sensor_adr[m.sensor("gyro").id])
        self.nsample = int(m.actuator_history[0, 0])
        self.nstate = mujoco.mj_stateSize(m, mujoco.mjtState.mjSTATE_FULLPHYSICS)
        self._data = mujoco.MjData(m)

    def initial_state(self, m: mujoco.MjModel, q: np.ndarray, dq: np.ndarray | None, cmd_hist: np.ndarray,
                      base: dict | None = None) -> np.ndarray:
        """Full physics state (``mjSTATE_FULLPHYSICS``) for a replay start.

        Args:
            m: the (edited) model the state is for.
            q: (n,) physical joint angles [rad]; dq: (n,) [rad/s] or None (zero).
            cmd_hist: (nsample, n) joint targets at the history buffer's time stamps
                (oldest first; the last row is the command active just before the start).
            base: floating base ``pos`` (3), ``quat`` (4, wxyz), ``linvel`` (3, world),
                ``angvel`` (3, world); ignored for a fixed base.
        """
        d = self._data
        mujoco.mj_resetData(m, d)
        d.qpos[self.qadr] = q
        if dq is not None:
            d.qvel[self.dadr] = dq
        if not self.structure.fixed_base and base is not None:
            d.qpos[0:3] = base["pos"]
            d.qpos[3:7] = base["quat"]
            R = quat_to_mat(np.asarray(base["quat"], dtype=float))
            d.qvel[0:3] = base.get("linvel", np.zeros(3))
            d.qvel[3:6] = R.T @ np.asarray(base.get("angvel", np.zeros(3)))
        if self.spring_jnt:  # springs start at their static deflection under the gravity load
            mujoco.mj_forward(m, d)
            for i, n in enumerate(self.robot.joint_names):
                if n in self.spring_jnt:
                    k = float(m.jnt_stiffness[self.spring_jnt[n]])
                    s = -float(d.qfrc_bias[self.spring_dadr[n]]) / k
                    d.qpos[self.spring_qadr[n]] = s
                    d.qpos[self.qadr[i]] = q[i] - s
        d.ctrl[self.act] = cmd_hist[-1]
        if m.na:
            d.act[m.actuator_actadr[self.act]] = cmd_hist[-1]  # the command filters hold the last command
        for i, a in enumerate(self.act):
            mujoco.mj_initCtrlHistory(m, d, int(a), None, np.ascontiguousarray(cmd_hist[:, i:i + 1]))
        st = np.empty(self.nstate)
        mujoco.mj_getState(m, d, st, mujoco.mjtState.mjSTATE_FULLPHYSICS)
        return st


def set_terrain(m: mujoco.MjModel, heights: np.ndarray) -> None:
    """Write ground heights [m], shape (ny, nx) of a ``terrain`` structure's grid (row = y, from
    -half y), into ``m`` (a copy of a ``terrain`` replay model).

    Raises:
        ValueError: wrong shape, or a height outside +-TERRAIN_RANGE/2.
    """
    hid = m.hfield("ground_hfield").id
    ny, nx = int(m.hfield_nrow[hid]), int(m.hfield_ncol[hid])
    h = np.asarray(heights, dtype=float)
    if h.shape != (ny, nx):
        raise ValueError(f"terrain heights must have shape {(ny, nx)}, got {h.shape}")
    if np.any(np.abs(h) > TERRAIN_RANGE / 2):
        raise ValueError(f"terrain heights must lie within +-{TERRAIN_RANGE / 2} m")
    adr = int(m.hfield_adr[hid])
    m.hfield_data[adr:adr + nx * ny] = (h.ravel() + TERRAIN_RANGE / 2) / TERRAIN_RANGE


@functools.lru_cache(maxsize=8)
def spring_stiffness_max(fixed_base: bool = True, physics_dt: float = PHYSICS_DT, robot_name: str = "nao") -> dict:
    """Stiffest series spring [N m/rad] per robot joint that the Euler step integrates stably.

    The spring force is explicit: the output side needs ``k dt^2 / I_out < 2`` (I_out: the joint's
    effective inertia, 1 / (M^-1)_ii of the sim's mass matrix at the reference pose) and the motor
    side ``dt^2 (kp + k) / I_m < 2`` (I_m: :func:`spring_motor_armature`). The returned value keeps
    a factor 2 margin on both.

    Args:
        robot_name: the robot (``RobotModel.name``, e.g. ``"nao"``, ``"g1"``).

    Returns:
        dict joint name -> k_max [N m/rad] (the smallest compliance a candidate can represent is
        1 / k_max; a stiffer transmission is, at this step size, a rigid one).

    Raises:
        KeyError: an unknown robot name.
    """
    robot = replay_model(Structure(fixed_base=fixed_base, physics_dt=physics_dt, robot=robot_name)).robot
    m = base_spec(robot, fixed_base=fixed_base, physics_dt=physics_dt).compile()
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    M = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, M)
    Minv = np.linalg.inv(M)
    out = {}
    for n, kp, kd in zip(robot.joint_names, robot.kp, robot.kd):
        i = int(m.jnt_dofadr[m.joint(n).id])
        k_out = 1.0 / (Minv[i, i] * physics_dt ** 2)
        k_motor = spring_motor_armature(float(kp), float(kd), physics_dt) / physics_dt ** 2 - float(kp)
        out[n] = float(min(k_out, k_motor))
    return out


@functools.lru_cache(maxsize=8)
def joint_inertia(robot_name: str = "nao", fixed_base: bool = True) -> dict:
    """Effective inertia [kg m^2] of each joint of the robot ``robot_name``: 1 / (M^-1)_ii of the
    sim's mass matrix at the zero pose (hanging robot for ``fixed_base``).

    Raises:
        KeyError: an unknown robot name.
    """
    robot = get_robot(robot_name)
    m = base_spec(robot, fixed_base=fixed_base, physics_dt=PHYSICS_DT, hang_height=robot.hang_height).compile()
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    M = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, M)
    Minv = np.linalg.inv(M)
    return {n: float(1.0 / Minv[i, i]) for n in robot.joint_names for i in [int(m.jnt_dofadr[m.joint(n).id])]}


@functools.lru_cache(maxsize=64)
def replay_model(structure: Structure, robot_name: str | None = None) -> ReplayModel:
    """Cached :class:`ReplayModel` of ``structure`` (treat as read-only) for the robot
    ``structure.robot`` (or ``robot_name`` when given: the structure is then taken for that robot).

    Raises:
        ValueError: an unknown robot name (the robots of ``robots.get_robot``).
    """
    if robot_name is not None and robot_name != structure.robot:
        return replay_model(dataclasses.replace(structure, robot=robot_name))
    try:
        robot = get_robot(structure.robot)
    except KeyError:
        raise ValueError(f"no replay model for robot {structure.robot!r}; this package models the robots of "
                         "robots.get_robot (nao, g1, talos)") from None
    return ReplayModel(robot, structure)
