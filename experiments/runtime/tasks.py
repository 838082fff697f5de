"""The work an executor runs: one walk episode, one grounding fit, one teacher-forced replay.

Each is a small frozen dataclass that pickles cheaply to a process-pool or Ray worker, and a
top-level function that runs it there:

* :class:`EpisodeTask` -> :func:`run_episode` -> :class:`EpisodeResult` (batched in lock-step by
  :func:`experiments.runtime.batch.map_episodes`);
* :class:`FitTask` -> :func:`fit_grounding_task` -> :class:`FitResult`;
* :class:`ReplayTask` -> :func:`replay_walk_task` -> :class:`ReplayResult`.

Workers build each world once per process (:func:`experiments.runtime.worlds.world_env`), so a
generation of CMA-ES builds each once; torch runs one thread in workers
(:mod:`experiments.runtime.executors`).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from common.defaults import EPISODE_SECONDS
from experiments.runtime.worlds import WorldSpec
from robots import get_robot

#: The physical worlds an episode runs in (a training world of :mod:`experiments.runtime.worlds` is one
#: of these with a transformer or noise on top).
ENGINE_WORLDS = ("sim", "real", "identified")


@dataclass(frozen=True)
class EpisodeTask:
    """One walk episode of the ZMP engine.

    Attributes:
        world: ``"sim"`` (MuJoCo), ``"real"`` (PyBullet) or ``"identified"`` (MuJoCo with the effects of
            the diagnosis reports ``identified``).
        theta: the gait parameters in SI units (``walk_engine.GaitParams.to_array`` of the robot).
        seed: the episode seed (terrain, effects, noise, SGAT sampling).
        seconds: episode length [s] (the paper: 7.5).
        robot: ``robots.get_robot`` name.
        profile: the real world's effect profile: a name (``envs.effects.PROFILES``), ``"NAME:mean"``
            (that profile with every effect at the middle of its range,
            :func:`experiments.runtime.worlds.mean_profile`) or a ``RealProfile`` dict (effect sweeps).
        stochasticity: the real world's per-step randomness level (``envs.effects.Stochasticity``; 0: none).
        identified: ``report.json`` paths of ``sgatwalk diagnose`` (the identified world, or the base
            of a grounded one: hybrid grounding).
        transformer: directory of a saved ``sgat.ActionTransformer``: the world grounded by it.
        action_noise: std [rad] of Gaussian noise on the applied leg targets (exploration noise of
            grounding walks, or the action-noise envelope).
        terrain: ``(kind, terrain seed, level)``: a ``terrain.make`` heightfield laid down at reset in
            place of the world's own ground (stress tests), or None.
        record: return the recording too.
        meta: extra metadata of the recording.
        key: the task's key in a run directory's episode log (resume); "" when not logged.

    Raises:
        ValueError: an unknown world, an identified world without reports, or reports for a robot
            other than the NAO; a negative stochasticity, or one outside the real world.
    """

    world: str
    theta: tuple
    seed: int
    seconds: float = EPISODE_SECONDS
    robot: str = "nao"
    profile: str | Mapping = "real"
    stochasticity: float = 0.0
    identified: tuple = ()
    transformer: str | None = None
    action_noise: float = 0.0
    terrain: tuple | None = None
    record: bool = False
    meta: Mapping = field(default_factory=dict)
    key: str = ""

    def __post_init__(self) -> None:
        if self.world not in ENGINE_WORLDS:
            raise ValueError(f"unknown world {self.world!r}; choose from {', '.join(ENGINE_WORLDS)}")
        object.__setattr__(self, "theta", tuple(float(x) for x in self.theta))
        object.__setattr__(self, "identified", tuple(self.identified or ()))
        object.__setattr__(self, "stochasticity", float(self.stochasticity))
        if not (math.isfinite(self.stochasticity) and self.stochasticity >= 0):
            raise ValueError(f"stochasticity must be a number >= 0, got {self.stochasticity!r}")
        if self.stochasticity and self.world != "real":
            raise ValueError(f"stochasticity is the real world's; the {self.world} world has none")
        if self.terrain is not None:
            kind, seed, level = self.terrain
            object.__setattr__(self, "terrain", (str(kind), int(seed), float(level)))
        if self.world == "identified" and not self.identified:
            raise ValueError("the identified world needs the diagnosis reports (identified)")
        if self.identified and self.robot != "nao":
            raise ValueError("the identified worlds model the NAO only (sgatwalk diagnose identifies the NAO)")

    def replace(self, **changes) -> EpisodeTask:
        """A copy with ``changes`` (``dataclasses.replace``)."""
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class EpisodeResult:
    """What one walk episode gave (:class:`experiments.runtime.fitness.WalkResult` and its seed).

    Attributes:
        seed: the episode seed.
        fitness: forward speed [cm/s] − 15 if it fell (the paper's reward).
        speed_cm_s: forward torso displacement / nominal duration [cm/s].
        fell, fall_reason, fall_time_s: whether, why (``"torso_low"``, ``"tilt"``, ``"unstable"``) and
            when [s] the episode ended in a fall.
        drift_m: lateral displacement |Δy| [m]; distance_m: forward displacement Δx [m].
        seconds: nominal duration [s]; steps: control steps walked.
        terrain: the name of the ground walked (``"flat"`` without a heightfield).
        wall_s: wall time of the episode [s] (a batch's time shared among its episodes).
        recording: ``(columns, meta)`` of the episode when its task asked for it, else None.
    """

    seed: int
    fitness: float
    speed_cm_s: float
    fell: bool
    fall_reason: str | None
    fall_time_s: float | None
    drift_m: float
    distance_m: float
    seconds: float
    steps: int
    terrain: str = "flat"
    wall_s: float = 0.0
    recording: tuple | None = None

    def metrics(self) -> dict:
        """The episode's figures as a dict (no recording, no wall time)."""
        return {k: v for k, v in dataclasses.asdict(self).items() if k not in ("recording", "wall_s")}


def episode_result(task: EpisodeTask, rec, res, wall_s: float = 0.0) -> EpisodeResult:
    """The :class:`EpisodeResult` of a finished walk of ``task`` (``rec`` an ``envs.Recording``, ``res``
    its :class:`experiments.runtime.fitness.WalkResult`); the recording carries the task's world and metadata."""
    rec.meta.update({"world": task.world, **task.meta})
    terrain = rec.meta.get("terrain")
    return EpisodeResult(seed=int(task.seed), **res.to_dict(), terrain=terrain["name"] if terrain else "flat",
                         wall_s=wall_s, recording=(rec.columns, rec.meta) if task.record else None)


def run_episode(task: EpisodeTask) -> EpisodeResult:
    """Run one walk episode (:class:`EpisodeTask`). A fall, a NaN or an exploding simulation is a
    result with ``fell`` True (reason ``"unstable"``), never an exception.

    Raises:
        ValueError: what building the task's world raises (an unknown profile, unreadable reports).
    """
    from experiments.runtime.fitness import run_walk  # lazy: loads the engines
    from experiments.runtime.worlds import task_env  # lazy: loads the engines
    from walk_engine import params_for  # lazy: scipy

    t0 = time.perf_counter()
    env = task_env(task)
    params = params_for(env.unwrapped.robot).from_array(np.asarray(task.theta, dtype=float))
    rec, res = run_walk(params, seed=int(task.seed), seconds=float(task.seconds), env=env)
    return episode_result(task, rec, res, time.perf_counter() - t0)


# ------------------------------------------------------------------------------------------- fits
@dataclass(frozen=True)
class FitTask:
    """One grounding step's fit of an action transformer (:func:`fit_grounding_task`).

    Attributes:
        real, sim: paths of the real and sim walk recordings (Parquet).
        config: the :class:`sgat.grounding.GroundingConfig` as a dict.
        history: frames of grounding state the models see.
        seed: seed of the fits.
        out: directory the transformer is saved to.
        robot: ``robots.get_robot`` name.
        label: what the fit is for, in messages (e.g. ``"sgat draw 2"``).
    """

    real: tuple
    sim: tuple
    config: Mapping
    history: int
    seed: int
    out: str
    robot: str = "nao"
    label: str = ""


@dataclass(frozen=True)
class FitResult:
    """A finished fit: where it was saved, the members' mean validation losses, the transitions used."""

    out: str
    forward_val: float
    inverse_val: float
    n_real: int
    n_sim: int
    wall_s: float


def fit_grounding_task(task: FitTask) -> FitResult:
    """Fit and save the action transformer of one grounding step (:func:`experiments.runtime.grounding.fit_walk_grounding`).

    Raises:
        FileNotFoundError: a recording is missing. ValueError: unusable data.
    """
    from envs import Recording  # lazy: loads the engines
    from experiments.runtime.grounding import fit_walk_grounding  # lazy: loads torch (sgat)
    from sgat.grounding import GroundingConfig  # lazy: sgat loads torch

    t0 = time.perf_counter()
    cfg = GroundingConfig(**{**task.config, "hidden": tuple(task.config["hidden"])})
    fit = fit_walk_grounding([Recording.from_parquet(p) for p in task.real], [Recording.from_parquet(p) for p in task.sim],
                             cfg, history=int(task.history), seed=int(task.seed), robot=task.robot)
    fit.transformer.save(task.out)
    return FitResult(task.out, float(np.mean([r.val_loss for r in fit.forward_reports])),
                     float(np.mean([r.val_loss for r in fit.inverse_reports])), fit.info["n_real"], fit.info["n_sim"],
                     time.perf_counter() - t0)


# ---------------------------------------------------------------------------------------- replays
@dataclass(frozen=True)
class ReplayTask:
    """Teacher-forcing the grounded sim along one recorded real walk (:func:`replay_walk_task`).

    Attributes:
        recording: the real walk's Parquet path (its seed is the episode's).
        transformer: directory of the fitted transformer.
        theta: the walk's gait (SI).
        seconds: episode length [s]; after the recording ends the sim walks on ungrounded.
        identified: report paths of the identified sim the transformer grounds (hybrid), or ().
        robot: ``robots.get_robot`` name.
    """

    recording: str
    transformer: str
    theta: tuple
    seconds: float = EPISODE_SECONDS
    identified: tuple = ()
    robot: str = "nao"


@dataclass(frozen=True)
class ReplayResult:
    """A teacher-forced replay: whether and when the sim fell, the same of the real walk, and the RMS
    error of the leg joint angles against the real walk over its length [rad], teacher-forced and
    with the sim ungrounded (what the tracking closes)."""

    fell: bool
    fall_time_s: float | None
    real_fell: bool
    real_fall_time_s: float | None
    q_rms_rad: float
    q_rms_plain_rad: float


def replay_walk_task(task: ReplayTask) -> ReplayResult:
    """Teacher-force the grounded sim along one recorded real walk (``sgat.TeacherForcedEnv``).

    Raises:
        FileNotFoundError: the recording or the transformer is missing.
    """
    from envs import ObservationLayout, Recording  # lazy: loads the engines
    from experiments.runtime.fitness import run_walk  # lazy: loads the engines
    from experiments.runtime.worlds import load_transformer, task_env  # lazy: loads the engines
    from sgat.grounding import recording_observations  # lazy: sgat loads torch
    from sgat.transformer import TeacherForcedEnv  # lazy: sgat loads torch
    from walk_engine import params_for  # lazy: scipy

    rec = Recording.from_parquet(task.recording)
    tr = load_transformer(task.transformer)
    robot = get_robot(task.robot)
    layout = ObservationLayout(robot)
    ref = tr.spec.states(recording_observations(rec, layout))
    seed, seconds = int(rec.meta.get("seed", 0)), float(task.seconds)
    base = task_env(EpisodeTask("identified" if task.identified else "sim", task.theta, seed, seconds, robot=task.robot,
                                identified=task.identified))
    params = params_for(robot).from_array(np.asarray(task.theta, dtype=float))
    nq = len(robot.groups["legs"])

    def q_rms(r) -> float:
        S = tr.spec.states(recording_observations(r, layout))
        n = min(len(S), len(ref))
        return float(np.sqrt(np.mean((S[:n, :nq] - ref[:n, :nq]) ** 2)))

    forced, res = run_walk(params, seed=seed, seconds=seconds, env=TeacherForcedEnv(base, tr, ref))
    plain, _ = run_walk(params, seed=seed, seconds=seconds, env=base)
    return ReplayResult(bool(res.fell), res.fall_time_s, bool(rec.meta.get("fell", False)), rec.meta.get("fall_time"),
                        q_rms(forced), q_rms(plain))



def episode_task(spec: WorldSpec, theta, seed: int, *, seconds: float, robot: str = "nao", profile="real",
                 stochasticity: float = 0.0, transformer: str | None = None, identified=(), record: bool = False,
                 key: str = "", meta=None):
    """The :class:`experiments.runtime.tasks.EpisodeTask` of one episode in the training world ``spec``.

    Args:
        spec: the training world.
        theta: the gait (SI); seed: the episode seed; seconds: its length [s].
        profile: the real world's profile (the ``real`` world, ``real:mean=1`` its mean physics).
        stochasticity: the real world's per-step randomness level (the ``real`` world only).
        transformer: the grounded worlds' fitted transformer (a directory).
        identified: the identified worlds' diagnosis reports.

    Raises:
        ValueError: a grounded world without ``transformer``, an identified one without ``identified``.
    """
    if spec.grounded and not transformer:
        raise ValueError(f"world {spec.name!r} needs its fitted transformer")
    if spec.needs_identification and not identified:
        raise ValueError(f"world {spec.name!r} needs the real world's identification (its reports)")
    kw: dict[str, Any] = {"robot": robot, "record": record, "key": key, "meta": dict(meta or {})}
    if spec.kind == "real":
        kw.update(world="real", profile=f"{profile}:mean" if spec.get("mean") else profile, stochasticity=stochasticity)
    elif spec.needs_identification:
        kw.update(world="identified", identified=tuple(identified))
    else:
        kw.update(world="sim")
    if spec.grounded:
        kw["transformer"] = transformer
    return EpisodeTask(theta=tuple(theta), seed=int(seed), seconds=float(seconds), action_noise=spec.noise, **kw)


__all__ = ["ENGINE_WORLDS", "EpisodeResult", "EpisodeTask", "FitResult", "FitTask", "ReplayResult", "ReplayTask",
           "episode_result", "episode_task", "fit_grounding_task", "replay_walk_task", "run_episode"]
