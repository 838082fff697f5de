"""Batched walk episodes: many :func:`experiments.runtime.tasks.run_episode` tasks in lock-step in one worker.

:func:`run_batch` takes a list of :class:`experiments.runtime.tasks.EpisodeTask` and returns exactly what
``[run_episode(t) for t in tasks]`` returns, bit for bit (``tests/test_batch.py``), faster: tasks of
a MuJoCo world (``sim``, ``identified``, grounded on either, with action noise, on a given heightfield) run as one
:class:`envs.batch.SimBatch` (one ``MjModel``, one ``MjData`` per episode; a model per episode
where the world builds one per episode, as the identified sim on its random ground) driven by one
:class:`walk_engine.batch.BatchWalkEngine` (the ZMP engine vectorized over the episodes), the
grounding transformer called once per control step for the batch (each episode with its own
generator and ensemble member) and the ANE noise per episode. Tasks of the PyBullet ``real``
world run one by one through ``run_episode``.

Per control step each active episode costs its ``mj_step`` calls plus a few microseconds of
array work; episodes that fall leave the batch. ``benchmarks/bench_generation.py`` measures the
ratio to bare ``mj_step``.
"""

from __future__ import annotations

import copy
import time

import numpy as np

from common.defaults import CONTROL_DT
from envs.batch import SimBatch
from envs.mujoco_world import SimWorld
from envs.rollout import assemble_recording
from envs.wrappers import ActionMismatch
from experiments.runtime.fitness import walk_fitness, walk_meta
from experiments.runtime.grounding import walk_spec
from experiments.runtime.tasks import EpisodeResult, EpisodeTask, episode_result, run_episode
from experiments.runtime.worlds import load_transformer, terrain_field, world_env
from walk_engine import GaitParams
from walk_engine.batch import BatchWalkEngine


def _batchable(task: EpisodeTask) -> bool:
    # BatchWalkEngine vectorizes the NAO's closed-form legs; other robots' episodes run one by one
    return task.world in ("sim", "identified") and task.robot == "nao"


def _group_key(task: EpisodeTask) -> tuple:
    """Tasks that share a world (and so a template env: :func:`experiments.runtime.worlds.world_env`), a
    transformer and a duration."""
    return task.world, task.transformer, float(task.seconds), task.identified, task.terrain is not None


def run_batch(tasks: list[EpisodeTask]) -> list[EpisodeResult]:
    """Run walk episodes in lock-step where the world allows it; results in task order.

    Args:
        tasks: :class:`experiments.runtime.tasks.EpisodeTask` (any worlds, any mix).

    Returns:
        ``[run_episode(t) for t in tasks]``, bit-identical (recordings included when asked; ``wall_s``
        is a batch's time shared among its episodes).

    Raises:
        ValueError: what ``run_episode`` raises for a bad task (unknown profile, missing reports).
    """
    tasks = list(tasks)
    out: list = [None] * len(tasks)
    groups: dict = {}
    for i, t in enumerate(tasks):
        if _batchable(t):
            groups.setdefault(_group_key(t), []).append(i)
        else:
            out[i] = run_episode(t)
    for idx in groups.values():
        for i, r in zip(idx, _run_sim_group([tasks[i] for i in idx])):
            out[i] = r
    return out


def _run_sim_group(tasks: list[EpisodeTask]) -> list[EpisodeResult]:
    """One group of sim-world tasks with the same world, transformer and duration."""
    t0 = time.perf_counter()
    env = world_env(tasks[0])
    tr = load_transformer(tasks[0].transformer) if tasks[0].transformer else None
    walks = lockstep_walks(env, [t.theta for t in tasks], [int(t.seed) for t in tasks], float(tasks[0].seconds),
                           terrains=[terrain_field(*t.terrain) if t.terrain else None for t in tasks]
                           if any(t.terrain for t in tasks) else None,
                           action_noise=[float(t.action_noise) for t in tasks], transformer=tr)
    wall = (time.perf_counter() - t0) / len(tasks)
    return [episode_result(t, rec, res, wall) for t, (rec, res) in zip(tasks, walks)]


class _GroundedBatch:
    """``sgat.GroundedEnv`` for B episodes at once: each episode its own copy of the transformer (its
    generator and ensemble member), its state history, its past commands and, with a delay, the
    actions it sent; every step one :meth:`sgat.transformer.ActionTransformer.transform_episodes` call."""

    def __init__(self, tr, B: int, n: int):
        self.tr, self.spec = tr, tr.spec
        spec = tr.spec
        self.eps = [copy.copy(tr) for _ in range(B)]
        self.H = np.empty((B, spec.history, spec.state_dim))
        self.P = np.empty((B, tr.commands, spec.action_dim)) if tr.commands else None  # each episode's past commands
        self.E = np.empty((B, tr.delay, spec.action_dim)) if tr.delay else None  # ... and the actions sent before
        self.Z = np.empty((B, n, tr.noise_dim)) if tr.samples else None

    def start(self, i: int, seed: int, obs: np.ndarray) -> None:
        """Episode ``i`` begins: its generator reseeded (and its member drawn), its history filled."""
        self.eps[i].reset(seed)
        self.H[i] = self.spec.states(obs)
        if self.Z is not None:  # the episode's SGAT noise, drawn at once: the same numbers, step by step
            self.Z[i] = self.eps[i].rng.standard_normal(self.Z.shape[1:])

    def ground(self, idx: np.ndarray, k: int, cmd: np.ndarray) -> np.ndarray:
        """The actions to apply at step ``k`` for the commands ``cmd`` (len(idx), n_act) of episodes ``idx``."""
        tr, ai = self.tr, self.spec.action_index
        act = cmd.copy()
        past = sent = None
        if self.P is not None:
            if k == 0:  # padded with the first command, as sgat.GroundedEnv and sgat.grounding.stack_past
                self.P[idx] = cmd[:, ai][:, None]
            past = self.P[idx].reshape(len(idx), -1)
        if self.E is not None:
            if k == 0:  # padded with the first command, as sgat.GroundedEnv pads
                self.E[idx] = cmd[:, ai][:, None]
            sent = self.E[idx].reshape(len(idx), -1)
        act[:, ai] = tr.transform_episodes(self.H[idx].reshape(len(idx), -1), cmd[:, ai], [self.eps[i].member for i in idx],
                                           None if self.Z is None else self.Z[idx, k], past, sent)
        if self.E is not None:
            self.E[idx] = np.concatenate([self.E[idx, 1:], act[:, ai][:, None]], axis=1)
        if self.P is not None:
            self.P[idx] = np.concatenate([self.P[idx, 1:], cmd[:, ai][:, None]], axis=1)
        return act

    def observe(self, live: np.ndarray, obs: np.ndarray) -> None:
        """The episodes still walking append their new state to their history."""
        self.H[live] = np.concatenate([self.H[live, 1:], self.spec.states(obs[live])[:, None]], axis=1)


def lockstep_walks(env: SimWorld, thetas, seeds, seconds: float, *, terrains=None, action_noise=None,
                   transformer=None) -> list:
    """Walk B gaits of the ZMP engine in the sim ``env`` in lock-step (see the module docstring).

    Args:
        env: a :class:`envs.SimWorld`, or a subclass with ``batch_hooks`` (the identified sim), the
            template (its state is restored afterwards).
        thetas: B gait parameter vectors (SI, 16); seeds: B episode seeds; seconds: episode length [s].
        terrains: B heightfields (or None: the env's own ground) to walk on, each episode its own.
        action_noise: B std [rad] of Gaussian noise on the applied leg targets (the ANE baseline or
            exploration noise, as :class:`envs.wrappers.ActionMismatch` with the episode's seed).
        transformer: an :class:`sgat.ActionTransformer` grounding every episode (the grounded sim,
            as :class:`sgat.GroundedEnv`; each episode its own generator and ensemble member).

    Returns:
        B ``(Recording, WalkResult)``, each bit-identical to
        :func:`experiments.runtime.fitness.run_walk` of that episode alone in the same (wrapped) world.

    Raises:
        ValueError: B differs between the arguments.
    """
    B = len(thetas)
    seeds = [int(s) for s in seeds]
    sigma = list(action_noise) if action_noise is not None else [0.0] * B
    if len(seeds) != B or len(sigma) != B or (terrains is not None and len(terrains) != B):
        raise ValueError(f"lockstep_walks: {B} gaits but {len(seeds)} seeds, {len(sigma)} noise levels"
                         + ("" if terrains is None else f", {len(list(terrains))} terrains"))
    n = int(round(seconds / env.control_dt))
    sim = SimBatch(env, B)
    # the wrappers of experiments.runtime.worlds.task_env, one per episode (their state is per episode)
    noise = [ActionMismatch(env, noise_std=s, index=walk_spec().action_index, seed=seeds[i]) if s > 0 else None
             for i, s in enumerate(sigma)]
    grounding = _GroundedBatch(transformer, B, n) if transformer is not None and not transformer.is_identity else None
    params = [GaitParams.from_array(np.asarray(th, dtype=float)) for th in thetas]
    engine = BatchWalkEngine(env.robot, params, dt=env.control_dt)
    sim.reset(seeds, None if terrains is None else list(terrains))
    for i in range(B):
        if noise[i] is not None:
            noise[i].reseed(seeds[i])
        if grounding is not None:
            grounding.start(i, seeds[i], sim.obs[i])
    engine.reset(sim.obs)
    tape = _Tape(env, B, n)
    _walk(sim, engine, grounding, noise, tape, n)
    return [(rec, walk_fitness(rec, seconds)) for rec in
            (assemble_recording(env, tape.O[i], tape.C[i], tape.A[i], tape.G[i], int(tape.rows[i]), seed=seeds[i],
                                seconds=seconds, fell=sim.reason[i] is not None, reason=sim.reason[i],
                                fall_time=tape.fall_time[i], meta=walk_meta(params[i]), terrain=sim.terrain(i))
             for i in range(B))]


class _Tape:
    """What a lock-step walk records per episode and control step: observations ``O``, commands ``C``,
    applied targets ``A``, ground truth ``G``, rows walked and the time of each fall."""

    def __init__(self, env, B: int, n: int):
        na = env.action_space.shape[0]
        self.O = np.empty((B, n, env.layout.size))
        self.C = np.empty((B, n, na))
        self.A = np.empty((B, n, na))
        self.G = np.full((B, n, 22), np.nan)
        self.rows = np.zeros(B, dtype=int)
        self.fall_time: list = [None] * B
        self.dt = env.control_dt


def _walk(sim, engine, grounding, noise, tape: _Tape, n: int) -> None:
    """The control loop of :func:`lockstep_walks`: every step, the episodes still walking are observed,
    commanded by the engine, grounded, perturbed and stepped; an episode that falls leaves the batch."""
    noisy = np.array([x is not None for x in noise])
    actions = np.zeros(tape.C.shape[::2])
    for k in range(n):
        idx = np.flatnonzero(sim.active)
        if not len(idx):
            break
        tape.O[idx, k] = sim.obs[idx]
        tape.G[idx, k, :19] = sim.gt[idx]
        cmd = engine.step(sim.obs, idx)
        tape.C[idx, k] = cmd
        act = grounding.ground(idx, k, cmd) if grounding is not None else cmd.copy()
        actions[idx] = act
        for j in np.flatnonzero(noisy[idx]).tolist():
            actions[idx[j]] = noise[idx[j]].perturb(act[j])
        sim.step(actions)
        tape.A[idx, k] = sim.applied[idx]
        tape.rows[idx] = k + 1
        for i in idx[~sim.active[idx]]:
            tape.fall_time[i] = (k + 1) * tape.dt
        if grounding is not None:
            grounding.observe(idx[sim.active[idx]], sim.obs)


#: Most episodes in one batch by default: a paper-scale population (150) on 2 workers is 2 batches;
#: the per-episode overhead barely falls beyond ~75 (benchmarks/bench_generation.py).
MAX_BATCH = 75


def chunk_tasks(tasks: list, workers: int = 1, batch_size: int | None = None, key=None) -> list[list[int]]:
    """Split task indices into batches for :func:`run_batch` (or another batched task function).

    Tasks that can run in lock-step (same world, transformer and duration; or the same ``key(task)``
    when a key function is given, None meaning "not batchable") are cut into
    ``ceil(n / workers)``-sized batches (at most ``batch_size``, default :data:`MAX_BATCH`), so
    every worker gets a share; every other task is a batch of its own.

    Returns:
        Lists of indices into ``tasks``, every index exactly once.

    Raises:
        ValueError: workers or batch_size < 1.
    """
    if workers < 1 or (batch_size is not None and batch_size < 1):
        raise ValueError(f"workers and batch_size must be >= 1, got {workers}, {batch_size}")
    cap = MAX_BATCH if batch_size is None else int(batch_size)
    groups: dict = {}
    out: list[list[int]] = []
    key = key or (lambda t: _group_key(t) if _batchable(t) else None)
    for i, t in enumerate(tasks):
        k = key(t)
        if k is not None:
            groups.setdefault(k, []).append(i)
        else:
            out.append([i])
    for idx in groups.values():
        size = min(cap, -(-len(idx) // workers))
        out.extend(idx[k:k + size] for k in range(0, len(idx), size))
    return out


def map_episodes(ex, tasks: list[EpisodeTask], progress=None, batch_size: int | None = None) -> list[EpisodeResult]:
    """``[run_episode(t) for t in tasks]`` on the executor ``ex``, sent as batches (:func:`chunk_tasks`).

    The results are bit-identical whatever the batch size and the number of workers
    (``tests/test_batch.py``). ``progress(n)`` is called with the number of episodes of each
    finished batch.
    """
    tasks = list(tasks)
    chunks = chunk_tasks(tasks, getattr(ex, "workers", 1), batch_size)
    res = ex.map(run_batch, [[tasks[i] for i in c] for c in chunks], progress=progress,
                 weights=[len(c) for c in chunks])
    out: list = [None] * len(tasks)
    for c, r in zip(chunks, res):
        for i, x in zip(c, r):
            out[i] = x
    return out


#: Control steps of the two trial walks that price a generation (:func:`expected_generation_seconds`):
#: their difference gives the time per control step, the shorter one the time per batch besides.
TRIAL_STEPS = (10, 110)


def expected_generation_seconds(task: EpisodeTask, episodes: int, workers: int) -> dict:
    """How long a generation of ``episodes`` episodes like ``task`` should take on ``workers`` cores,
    timed on a trial of the task's own world in this process.

    The executors cut a generation into batches (:func:`chunk_tasks`: ``ceil(episodes / workers)``
    episodes each, at most :data:`MAX_BATCH`) of which each worker runs ``rounds`` one after the other.
    The trial walks one such batch of the task (its world, ground, transformer and gait; seeds 0, 1,
    ...) twice, for :data:`TRIAL_STEPS` control steps (after a 2-step walk that builds the world and
    loads the transformer, as a worker's first batch does): the difference of the two times is the
    batch's time per control step (the physics of every episode, the walk engine, the transformer and
    the bookkeeping), the shorter one less its steps the time per batch besides (the episodes' resets:
    the identified sim compiles a model per episode on its own ground). A task that does not run
    batched (the real world, a robot other than the NAO) is timed as one episode the same way. The
    trial costs about 120 control steps of one batch (about 2 s for the hybrid default's batches of 6).

    The estimate assumes that no episode falls (a fallen episode leaves its batch): a generation
    whose episodes fall ends sooner. The trial walks the gait's first 1.1 s, whose start in double
    support costs more per step than the walk after it (for θ0 on the identified ground, a fifth to
    a third more than its 5 s walk's average, measured): the estimate reads high even where none
    falls. It is timed on a shared machine and varies by a fifth between calls there.

    Args:
        task: an :class:`experiments.runtime.tasks.EpisodeTask` (its ``seconds`` is the episode length;
            ``seed``, ``record``, ``meta`` and ``key`` are replaced for the trial).
        episodes: episodes per generation (>= 1).
        workers: worker processes (>= 1).

    Returns:
        ``{"expected_s", "batch": episodes per batch, "rounds": batches per worker, "step_ms": time per
        control step of a batch [ms], "batch_fixed_s": time per batch besides its steps [s]}``.

    Raises:
        ValueError: episodes or workers < 1; what ``run_episode`` raises for a bad task.
    """
    if episodes < 1 or workers < 1:
        raise ValueError(f"episodes and workers must be >= 1, got {episodes}, {workers}")
    n = int(round(float(task.seconds) / CONTROL_DT))
    base = task.replace(record=False, meta={}, key="")
    chunks = chunk_tasks([base] * episodes, workers)  # the generation's batches, as map_episodes cuts them
    size, rounds = len(chunks[0]), -(-len(chunks) // workers)
    # run_batch walks a task that does not run batched one episode at a time, as the executors do
    run_batch([base.replace(seed=0, seconds=2 * CONTROL_DT)])  # the world built, the transformer loaded (cached per process)
    took = []
    for steps in TRIAL_STEPS:
        trial = [base.replace(seed=k, seconds=steps * CONTROL_DT) for k in range(size)]
        t0 = time.perf_counter()
        run_batch(trial)
        took.append(time.perf_counter() - t0)
    step = max(0.0, (took[1] - took[0]) / (TRIAL_STEPS[1] - TRIAL_STEPS[0]))
    fixed = max(0.0, took[0] - TRIAL_STEPS[0] * step)
    return {"expected_s": rounds * (fixed + n * step), "batch": size, "rounds": rounds, "step_ms": 1e3 * step,
            "batch_fixed_s": fixed}
