"""The deterministic "sim": the NAO-like robot in MuJoCo, loaded from the shared URDF.

Model building (MuJoCo documentation: Model Editing (``MjSpec``), URDF import, XML reference
``hfield``):

* ``MjSpec.from_file(urdf)`` with ``fusestatic = False``; a free joint on ``torso`` (floating
  base), or the torso placed at ``hang_height`` with no joint (fixed base).
* The URDF ``<mimic>`` becomes MuJoCo's joint equality that couples ``RHipYawPitch`` to
  ``LHipYawPitch`` (one motor); no second equality is added.
* One actuator per joint implementing ``tau = kp (q* - q) - kd qdot`` clipped to the URDF effort
  (``gainprm = kp``, ``biasprm = (0, -kp, -kd)``, ``forcerange = +-effort``), evaluated explicitly
  each physics step like PyBullet's Python PD. No armature, no joint damping (PyBullet has
  neither), Euler integrator.
* Robot geoms collide with the ground only (``contype 1, conaffinity 0``); PyBullet's default
  (self-collision off) is the same rule. Friction ``NOMINAL_FOOT_FRICTION`` on every geom.
* Heightfield: ``nrow = ny``, ``ncol = nx``, ``size = (half_x, half_y, max - min, base)``, geom at
  ``z = min`` (MuJoCo rescales hfield data to [0, size[2]] above the geom), so its surface is
  :meth:`terrain.Heightfield.height_at`.
"""

from __future__ import annotations

import mujoco
import numpy as np

from common.spatial import cross, quat_to_mat
from envs.base import HumanoidEnv, StepState, make_terrain
from envs.effects import NOMINAL_FOOT_FRICTION
from robots import RobotModel
from terrain import Heightfield

_FLAT_ELEVATION = 1e-6  # MuJoCo needs a positive elevation range even for a constant field
#: Contact time constant of the sim's ground [s] (MuJoCo ``solref[0]``, damping ratio 1): a hard floor
#: (a standing robot sinks 0.2 mm; 0.6 mm with MuJoCo's 20 ms default). Windowed replays of 6 s
#: excitation logs without effects (leg joints' residual RMS, 1 mrad noise included): PyBullet's
#: 4.95 / 3.48 / 3.37 mrad at 20 / 10 / 5 ms, MuJoCo's own 2.86 / 3.03 / 3.37 (stiffer contacts
#: amplify the start-state noise); the sim's walking speeds match PyBullet's within 0.3 cm/s at 10 ms.
GROUND_TIMECONST = 0.01


def build_model(robot: RobotModel, terrain: Heightfield | None = None, *, fixed_base: bool = False,
                hang_height: float = 0.6, physics_dt: float = 0.002,
                friction: float = NOMINAL_FOOT_FRICTION) -> mujoco.MjModel:
    """Compile the MuJoCo model of ``robot`` on ``terrain`` (None: a plane at z = 0).

    Returns:
        ``mujoco.MjModel`` with 24 hinge joints (+ free joint unless ``fixed_base``), 24 PD
        actuators in ``robot.joint_names`` order, sites ``l_sole``, ``r_sole``, ``gyro``, ``accel``.
    """
    return build_spec(robot, terrain, fixed_base=fixed_base, hang_height=hang_height, physics_dt=physics_dt,
                      friction=friction).compile()


def build_spec(robot: RobotModel, terrain: Heightfield | None = None, *, fixed_base: bool = False,
               hang_height: float = 0.6, physics_dt: float = 0.002,
               friction: float = NOMINAL_FOOT_FRICTION) -> mujoco.MjSpec:
    """The uncompiled ``mujoco.MjSpec`` of :func:`build_model` (same arguments), for callers that
    add to the model before compiling it (``sysid.model`` adds delay buffers, sensors, play hinges).

    The ground geom is named ``ground``: a plane, or the heightfield ``terrain``.
    """
    spec = mujoco.MjSpec.from_file(robot.write_urdf())
    spec.compiler.fusestatic = False
    spec.option.timestep = physics_dt
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_EULER
    # Contacts of a hard floor (MuJoCo docs, "Computation > Contact"; measured against PyBullet's
    # near-rigid contacts by replaying its recordings, and against its walking speeds):
    # * elliptic friction cone, the Coulomb cone itself (a pyramid allows only mu/sqrt(2) along its
    #   diagonals; PyBullet clamps each tangent direction to mu);
    # * impratio 10 (frictional-to-normal impedance ratio): with 1 a loaded sole that should stick
    #   creeps about 12 mm over the 2-3.5 Hz slip segment of sysid.excitation at mu 0.8 (PyBullet
    #   0.1 mm); with 10 about 2 mm, while real slip stays (48 mm at mu 0.3);
    # * contact time constant GROUND_TIMECONST (solref) instead of MuJoCo's 20 ms default, a soft mat.
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.impratio = 10.0
    timeconst = max(GROUND_TIMECONST, 2.0 * physics_dt)  # MuJoCo needs >= 2 steps
    torso = spec.body(robot.root)
    if fixed_base:
        torso.pos = [0.0, 0.0, hang_height]
    else:
        torso.add_freejoint(name="root")
    for g in spec.geoms:
        g.contype, g.conaffinity = 1, 0
        g.friction = [friction, 0.005, 0.0001]
        g.solref = [timeconst, 1.0]
    for eq in spec.equalities:  # the HipYawPitch mimic: make it stiff (the default solref is 20 ms)
        eq.solref = [2 * physics_dt, 1.0]
        eq.solimp = [0.99, 0.999, 0.001, 0.5, 2.0]
    for name, fr in robot.frames.items():
        spec.body(fr.link).add_site(name=name, pos=list(fr.offset))
    for j in robot.joints:
        a = spec.add_actuator(name=j.name, target=j.name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        a.gaintype = mujoco.mjtGain.mjGAIN_FIXED
        a.biastype = mujoco.mjtBias.mjBIAS_AFFINE
        a.gainprm[0] = j.kp
        a.biasprm[0:3] = [0.0, -j.kp, -j.kd]
        a.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        a.forcerange = [-j.effort, j.effort]
    if terrain is None:
        ground = spec.worldbody.add_geom(name="ground", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 1])
    else:
        h = terrain.heights
        ny, nx = h.shape
        hx, hy = terrain.half_extent
        lo, hi = float(h.min()), float(h.max())
        hf = spec.add_hfield(name="terrain", nrow=ny, ncol=nx)
        hf.size = [hx, hy, max(hi - lo, _FLAT_ELEVATION), 0.05]
        hf.userdata = h.ravel().tolist()
        ground = spec.worldbody.add_geom(name="ground", type=mujoco.mjtGeom.mjGEOM_HFIELD, hfieldname="terrain",
                                         pos=[0.0, 0.0, lo])
    ground.contype, ground.conaffinity = 1, 1
    ground.friction = [friction, 0.005, 0.0001]
    ground.solref = [timeconst, 1.0]
    return spec


def foot_contact_sums(geom1, geom2, normal, pos, geom_foot, ground, episode=None, episodes: int = 1):
    """Total normal force and force-weighted contact point of each foot, from MuJoCo's contacts.

    Args:
        geom1, geom2: the contacts' geom ids (ncon,); normal: their normal forces [N] (ncon,) (elliptic
            cone: a contact's first constraint row, ``efc_force[efc_address]``, what ``mj_contactForce``
            returns as force[0]; MuJoCo docs, "Computation > Contact"); pos: contact points (ncon, 3).
        geom_foot: geom id -> 0 (left foot), 1 (right foot), -1 (other); ground: the ground geom id.
        episode, episodes: for contacts of several episodes concatenated: each contact's episode
            index (ncon,) and their number (batched rollouts, ``envs.batch``).

    Returns:
        (force (episodes, 2) [N], moment (episodes, 2, 3) = Σ f·p [N m]); divide by the force for
        the centre of pressure. Sums run in contact order (``np.bincount``), so one episode's sums
        are the same bit for bit alone or in a batch.
    """
    foot = np.where(geom2 == ground, geom_foot[geom1], np.where(geom1 == ground, geom_foot[geom2], -1))
    sel = foot >= 0
    grp = 2 * (0 if episode is None else episode[sel]) + foot[sel]
    fn = normal[sel]
    n = 2 * episodes
    force = np.bincount(grp, fn, minlength=n)
    mom = np.stack([np.bincount(grp, fn * pos[sel, c], minlength=n) for c in range(3)], axis=-1)
    return force.reshape(episodes, 2), mom.reshape(episodes, 2, 3)


class SimWorld(HumanoidEnv):
    """The MuJoCo "sim" world: deterministic, flat by default, optional heightfield.

    Args:
        robot, fixed_base, physics_dt, control_dt, initial_pose, hang_height, max_episode_seconds:
            see :class:`envs.base.HumanoidEnv`.
        terrain: None/"flat" (plane at z = 0) or a :class:`terrain.Heightfield`; a per-episode
            terrain can be passed as ``reset(options={"terrain": hf})``.
        friction: sliding friction of all contacts.

    Identical inputs give bit-identical trajectories (MuJoCo is deterministic on one thread).
    """

    world = "sim"

    def __init__(self, robot: RobotModel | None = None, *, terrain=None, friction: float = NOMINAL_FOOT_FRICTION,
                 **kwargs):
        super().__init__(robot, **kwargs)
        self.friction = float(friction)
        self._terrain = make_terrain(terrain)
        self._build()

    def _compile(self) -> mujoco.MjModel:
        """The world's model on the current terrain (a subclass may build another one with the same
        robot joints, actuators, sites and ``ground`` geom)."""
        return build_model(self.robot, self._terrain, fixed_base=self.fixed_base, hang_height=self.hang_height,
                           physics_dt=self.physics_dt, friction=self.friction)

    def _build(self) -> None:
        self.model = self._compile()
        self.data = mujoco.MjData(self.model)
        m = self.model
        self._qadr = np.array([m.jnt_qposadr[m.joint(n).id] for n in self.robot.joint_names])
        self._dadr = np.array([m.jnt_dofadr[m.joint(n).id] for n in self.robot.joint_names])
        self._torso = m.body(self.robot.root).id
        self._sites = {n: m.site(n).id for n in self.robot.frames}
        feet = {self.robot.frames["l_sole"].link: 0, self.robot.frames["r_sole"].link: 1}
        # geom id -> foot index (0 left, 1 right, -1 other)
        self._geom_foot = np.array([feet.get(m.body(m.geom_bodyid[g]).name, -1) for g in range(m.ngeom)])
        self._ground = m.geom("ground").id
        self._vel6 = np.zeros(6)

    # ---------------------------------------------------------------- engine hooks
    def _reset_world(self, seed, options) -> None:
        if "terrain" in options:
            new = make_terrain(options["terrain"])
            if new is not self._terrain:
                self._terrain = new
                self._build()
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        d.qpos[self._qadr] = self.q0
        d.ctrl[:] = self.q0
        if not self.fixed_base:
            d.qpos[3:7] = [1.0, 0.0, 0.0, 0.0]
            mujoco.mj_kinematics(m, d)
            soles = [d.site_xpos[self._sites[s]] for s in ("l_sole", "r_sole")]
            ground = max(float(self.terrain_height(p[0], p[1])) for p in soles)
            d.qpos[2] += ground - min(p[2] for p in soles) + 0.0005
        mujoco.mj_forward(m, d)
        self._warnings = self._bad_state_warnings()

    _BAD = (mujoco.mjtWarning.mjWARN_BADQPOS, mujoco.mjtWarning.mjWARN_BADQVEL, mujoco.mjtWarning.mjWARN_BADQACC)

    def _bad_state_warnings(self) -> int:
        """How often MuJoCo found NaN/huge qpos, qvel or qacc (it then resets the state itself)."""
        return sum(int(self.data.warning[w].number) for w in self._BAD)

    def _advance(self, targets: np.ndarray) -> None:
        self.data.ctrl[:] = targets
        mujoco.mj_step(self.model, self.data, nstep=self.n_substeps)

    def _state(self) -> StepState:
        m, d = self.model, self.data
        mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_BODY, self._torso, self._vel6, 0)
        angvel, linvel = self._vel6[:3].copy(), self._vel6[3:].copy()
        base_pos = d.xpos[self._torso].copy()
        base_quat = d.xquat[self._torso].copy()
        acc_site = d.site_xpos[self._sites["accel"]]
        accel_vel = linvel + cross(angvel, acc_site - base_pos)
        if d.ncon:
            con = d.contact
            force, cop = foot_contact_sums(con.geom1, con.geom2, d.efc_force[con.efc_address], con.pos,
                                           self._geom_foot, self._ground)
            force, cop = force[0], cop[0]
        else:
            force, cop = np.zeros(2), np.zeros((2, 3))
        with np.errstate(invalid="ignore", divide="ignore"):
            cop = np.where(force[:, None] > 0, cop / force[:, None], np.nan)
        q, dq = self._joint_state()
        if self._bad_state_warnings() > self._warnings:
            q[:] = np.nan  # MuJoCo reset the state after a bad qpos/qvel/qacc: report "unstable"
        return StepState(q, dq, base_pos, base_quat, linvel, angvel, accel_vel, force, cop)

    def _joint_state(self) -> tuple[np.ndarray, np.ndarray]:
        """The 24 joint angles [rad] and velocities [rad/s] the encoders measure."""
        return self.data.qpos[self._qadr].copy(), self.data.qvel[self._dadr].copy()

    def _com(self) -> np.ndarray:
        return self.data.subtree_com[self._torso].copy()

    def _to_sole(self, sole: str, p_world: np.ndarray) -> np.ndarray:
        sid = self._sites[sole]
        return self.data.site_xmat[sid].reshape(3, 3).T @ (p_world - self.data.site_xpos[sid])

    # ---------------------------------------------------------------- extras
    def set_state(self, q: np.ndarray, dq: np.ndarray | None = None, base_pos=None, base_quat=None,
                  base_linvel=None, base_angvel=None) -> None:
        """Overwrite the physics state (joint angles (24,) [rad] and, for a floating base, the torso
        pose and world velocities); used by replay tools."""
        d = self.data
        d.qpos[self._qadr] = q
        d.qvel[self._dadr] = 0.0 if dq is None else dq
        if not self.fixed_base:
            if base_pos is not None:
                d.qpos[0:3] = base_pos
            if base_quat is not None:
                d.qpos[3:7] = base_quat
            R = quat_to_mat(d.qpos[3:7])
            if base_linvel is not None:
                d.qvel[0:3] = base_linvel
            if base_angvel is not None:
                d.qvel[3:6] = R.T @ np.asarray(base_angvel)  # free joint angular velocity is local
        mujoco.mj_forward(self.model, d)


#: The name of this class when the project modelled the NAO only (kept for user code that uses it).
NaoSimEnv = SimWorld
