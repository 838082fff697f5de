"""The identified sim: the MuJoCo sim with the physics a diagnosis found, as a walking world.

``sgatwalk diagnose`` names the effects the sim leaves out and fits their values (``report.json``:
``model`` and ``base_model``, labels like ``latency`` or ``pd_gain[LKneePitch]``, values in SI
units; uneven ground as the RMS height of a random surface). :class:`IdentifiedSimEnv` is
:class:`envs.NaoSimEnv` with those effects built in by the same MuJoCo augmentations the diagnosis
replayed (:func:`sysid.candidates.apply_terms`: actuator delay buffers for latency, series play and
spring hinges for backlash and joint compliance, ``dof_frictionloss``, gains, effort limits, joint
stiffness for parallel springs, link masses, contact friction and time constant), so that what was
fitted is what is walked on:

* offsets of the logged angle (``sensor_bias``) are added to the measured angles; encoder calibration
  offsets (``encoder_offset``) are added to them and subtracted from the targets too (the servo reads
  the same encoder), as the diagnosis replayed them (:func:`sysid.candidates.readout`);
* the measured angle of a joint with a play or spring hinge is the sum of its hinges (the output),
  except behind a motor-shaft encoder (``backlash_link``: the motor hinge alone);
* a Stribeck friction (``stribeck_friction``, an extra actuator in the diagnosis's replays) is walked
  as Coulomb friction at the mean of its static and sliding levels (the walking world drives the
  robot's own actuators only);
* uneven ground (``terrain_roughness``) is a fresh Gaussian random surface of the fitted RMS height
  at every episode, drawn from the episode seed (:func:`terrain.gaussian`, the diagnosis's surface
  model with its 8 cm correlation radius), with the walking terrains' flat start pad;
* on that ground MuJoCo builds the constraint Jacobian sparse (:data:`GROUND_JACOBIAN`): the same
  equations as the plain sim's dense default, solved faster where a sole keeps many contacts.

This is the "identified" training world of ``sgatwalk fidelity`` and the base of the hybrid
grounding (SGAT on top of it, ``experiments.fidelity``).
"""

from __future__ import annotations

import json
import os

import mujoco
import numpy as np

from envs.mujoco_world import NaoSimEnv
from sysid.candidates import FAMILIES, Term, apply_terms, readout, series_structure
from sysid.model import ReplayModel, Structure
from sysid.report import terms_from_labels
from sysid.roughness import CORRELATION_RADIUS
from terrain import Heightfield, gaussian

#: MuJoCo's constraint Jacobian (``mjOption.jacobian``; MuJoCo documentation, XML reference
#: ``option/jacobian``) of the identified sim on uneven ground. MuJoCo's CPU engine keeps up to 50
#: contacts per sole-heightfield pair (``mjMAXCONPAIR``), each a few constraint rows that touch one
#: leg's dofs, so the rows are mostly zeros; the sparse form (MuJoCo's ``auto`` picks dense below 60
#: dofs, and the NAO has 30 plus its series hinges) cuts a physics step by 16-39 % on a heightfield
#: (``benchmarks/bench_ground.py``). It is a numerical setting, not physics: the model and the
#: equations are the dense ones', solved to the same tolerance, and a walk's states agree to a tenth
#: of a millimetre over its first second, until the walk's own sensitivity amplifies the difference
#: (as any change of summation order would; ``tests/test_identified.py``). The flat
#: identified sim keeps the plain sim's dense default, bit for bit.
GROUND_JACOBIAN = mujoco.mjtJacobian.mjJAC_SPARSE


def confounded_with_ground(rep: dict) -> set[str]:
    """Labels of a report's model terms that only stand in for its uneven ground: a contact term the
    diagnosis kept as uncertain (not a finding) and reported indistinguishable from a declared
    terrain roughness. The roughness is fitted on the residual before the contact terms
    (``sysid.diagnose``) and the contact term is then fitted to the same residual, so a world with
    both counts the ground's signature twice.

    Args:
        rep: a ``report.json`` of ``sgatwalk diagnose`` as a dict (``effects``, ``uncertain``,
            ``indistinguishable``, ``model``; missing keys count as empty).

    Returns:
        The labels of ``rep["model"]`` (e.g. ``{"ground_compliance"}``) to leave out; empty when the
        report declares no terrain roughness or every contact term is a finding.
    """
    if not any(e.get("family") == "terrain_roughness" for e in rep.get("effects", [])):
        return set()
    found = {e.get("family") for e in rep.get("effects", [])}
    unsure = {e.get("family") for e in rep.get("uncertain", [])} - found
    pairs = {p.get("a") for p in rep.get("indistinguishable", []) if p.get("b") == "terrain_roughness"}
    return {lab for lab in rep.get("model", {}) if lab in pairs and lab.split("[")[0] in unsure}


def load_identified(paths, confounded: bool = True) -> tuple[dict[Term, float], float]:
    """The identified physics of one or more diagnosis reports.

    Args:
        paths: ``report.json`` files (or folders holding one) of ``sgatwalk diagnose``; later reports
            override earlier ones term by term (a stepping-log diagnosis with ``--base-report`` already
            carries the fixed-base terms as its ``base_model``).
        confounded: False leaves out the contact terms that only stand in for the identified uneven
            ground (:func:`confounded_with_ground`); True (the default) builds in every model term.

    Returns:
        (terms: Term -> value in SI units, the RMS height [m] of the identified uneven ground or 0).

    Raises:
        FileNotFoundError: a path without a report. ValueError: not a report of ``sgatwalk diagnose``.
    """
    if isinstance(paths, (str, os.PathLike)):
        paths = [paths]
    terms: dict[Term, float] = {}
    rms = 0.0
    for p in paths:
        p = os.fspath(p)
        if os.path.isdir(p):
            p = os.path.join(p, "report.json")
        if not os.path.exists(p):
            raise FileNotFoundError(f"no diagnosis report at {p!r}")
        try:
            with open(p) as f:
                rep = json.load(f)
            drop = set() if confounded else confounded_with_ground(rep)  # the base model's own value stays
            terms.update(terms_from_labels({**rep.get("base_model", {}),
                                            **{k: v for k, v in rep["model"].items() if k not in drop}}))
        except (json.JSONDecodeError, KeyError, TypeError, AttributeError) as exc:
            raise ValueError(f"{p}: not a report.json of sgatwalk diagnose ({exc})") from None
        for e in rep.get("effects", []):
            if e.get("family") == "terrain_roughness":
                rms = float(e["value"])
    return terms, rms


def model_ground(seed: int | None, rms_height: float) -> Heightfield | None:
    """The identified sim's uneven ground of an episode: a Gaussian random surface of RMS height
    ``rms_height`` [m] (:func:`terrain.gaussian`, the diagnosis's surface model with its
    :data:`sysid.roughness.CORRELATION_RADIUS`, and the walking terrains' flat start pad) drawn from
    the episode seed, or None (flat) for height 0. :class:`IdentifiedSimEnv` walks this ground;
    another world given it (the real world's ``ground``) walks the very same surface for the same seed."""
    if rms_height <= 0:
        return None
    ss = np.random.SeedSequence([0 if seed is None else int(seed), 0x7e44])
    return gaussian(np.random.default_rng(ss), rms_height, CORRELATION_RADIUS)


class IdentifiedSimEnv(NaoSimEnv):
    """:class:`envs.NaoSimEnv` with identified effects (see the module docstring).

    Args:
        terms: Term -> value (SI), e.g. from :func:`load_identified`; an empty dict is the plain sim.
        rms_height: RMS height [m] of the uneven ground (0: the sim's own ground).
        ground: ``seed -> Heightfield | None``, the uneven ground of each episode in place of
            :func:`model_ground` of ``rms_height`` (e.g. the real world's lumpy terrain of the same
            seed, ``envs.bullet_world.real_ground``: the identified physics on the real ground).
        **kwargs: :class:`envs.NaoSimEnv` arguments (robot, fixed_base, physics_dt, ...). A ``terrain``
            given here (or as a reset option) replaces the random surfaces.

    Raises:
        ValueError: an unknown family, a stochastic family among ``terms``, or a negative height.
    """

    world = "identified"

    def __init__(self, terms: dict[Term, float] | None = None, rms_height: float = 0.0, ground=None, **kwargs):
        self.terms = {Term(t.family, t.target): float(v) for t, v in (terms or {}).items()}
        for t in self.terms:
            if t.family not in FAMILIES or FAMILIES[t.family].stochastic:
                raise ValueError(f"{t.label()}: not a deterministic effect family of the diagnosis")
        if not rms_height >= 0:
            raise ValueError(f"rms_height must be >= 0, got {rms_height}")
        self.rms_height = float(rms_height)
        self.ground = ground
        self._fixed_terrain = kwargs.get("terrain") is not None
        super().__init__(**kwargs)

    @classmethod
    def from_reports(cls, paths, confounded: bool = True, **kwargs) -> "IdentifiedSimEnv":
        """The world of :func:`load_identified` ``(paths, confounded)``."""
        terms, rms = load_identified(paths, confounded)
        return cls(terms, rms, **kwargs)

    def describe(self) -> dict:
        """Label -> value of every identified term, plus ``terrain_rms_height`` [m]."""
        return {**{t.label(): v for t, v in sorted(self.terms.items())}, "terrain_rms_height": self.rms_height}

    # ---------------------------------------------------------------- model
    def _walked_terms(self) -> dict:
        """The terms as walked: a Stribeck friction as Coulomb friction at the mean of its static and
        sliding levels (half its excess added to the joint's Coulomb term)."""
        out = {}
        for t, v in self.terms.items():
            if t.family == "stribeck_friction":
                c = Term("coulomb_friction", t.target)
                out[c] = out.get(c, 0.0) + 0.5 * v
            else:
                out[t] = out.get(t, 0.0) + v if t.family == "coulomb_friction" else v
        return out

    def _compile(self) -> mujoco.MjModel:
        terms = self._walked_terms()
        st = series_structure(Structure(fixed_base=self.fixed_base, physics_dt=self.physics_dt,
                                        hang_height=self.hang_height, friction=self.friction, robot=self.robot.name,
                                        command_filter=any(t.family == "command_lowpass" for t in terms)),
                              terms)
        self._rm = rm = ReplayModel(self.robot, st, ground=self._terrain)
        m = rm.model  # freshly compiled for this world: ours to edit
        self._bias = apply_terms(rm, m, terms)
        _, self._servo = readout(rm, terms)
        if self._terrain is not None:
            m.opt.jacobian = GROUND_JACOBIAN
        idx = {n: i for i, n in enumerate(self.robot.joint_names)}
        behind = {t.target for t in terms if t.family == "backlash_link"}  # the encoder reads the motor
        self._series = [(idx[n], int(rm.play_qadr[n]), int(rm.play_dadr[n])) for n in rm.play_jnt if n not in behind]
        self._series += [(idx[n], int(rm.spring_qadr[n]), int(rm.spring_dadr[n])) for n in rm.spring_jnt]
        return m

    def _reset_world(self, seed, options) -> None:
        options = dict(options)
        if "terrain" not in options and not self._fixed_terrain:
            if self.ground is not None:
                options["terrain"] = self.ground(seed)
            elif self.rms_height > 0:
                options["terrain"] = model_ground(seed, self.rms_height)
        super()._reset_world(seed, options)
        m, d = self.model, self.data
        for i, (a, q) in enumerate(zip(self._rm.act, self.q0 - self._servo)):
            d.ctrl[a] = q
            if m.actuator_history[a, 0] > 0:  # delay buffers hold the start pose, not zeros
                mujoco.mj_initCtrlHistory(m, d, int(a), None, np.full((int(m.actuator_history[a, 0]), 1), q))
        mujoco.mj_forward(m, d)

    def _advance(self, targets: np.ndarray) -> None:
        super()._advance(targets - self._servo)

    def _joint_state(self) -> tuple[np.ndarray, np.ndarray]:
        q, dq = super()._joint_state()
        d = self.data
        for i, qa, da in self._series:
            q[i] += d.qpos[qa]
            dq[i] += d.qvel[da]
        return q, dq

    def _sensor_noise(self, fields: dict[str, np.ndarray]) -> None:
        fields["q"] += self._bias

    def batch_hooks(self) -> dict:
        """What this world changes in the sim's step, for lock-step batches (:class:`envs.batch.SimBatch`):
        the offsets the servos see (``encoder_offset``, subtracted from the servo targets), those the
        log sees (``sensor_bias`` and ``encoder_offset``, added to the measured angles) and the series
        hinges whose angles add to the measured joint angles."""
        return {"ctrl_offset": self._servo.copy(), "q_offset": self._bias.copy(), "series": list(self._series)}
