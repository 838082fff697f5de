"""The walk rollout and its fitness: the SGAT paper's reward.

Reward (Desai et al., IROS 2020, §IV.C: "a sum of the forward velocity of the robot (in cm/s) and an
early termination penalty of -15 if the robot falls down"; docs/architecture.md "The main job, as data"):

    fitness = forward speed [cm/s] - 15 * fell,

where forward speed = forward displacement of the torso origin along the world x axis (the
robot starts facing +x) divided by the *nominal* episode duration (7.5 s by default), so a fall
also costs the distance not walked. Also reported: lateral drift (|Δy| of the torso), the time
and reason of a fall. Ground truth is read from the recording only here, never by the engine.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from common.defaults import EPISODE_SECONDS, FALL_PENALTY  # noqa: F401 - re-exported: experiments.runtime.fitness.FALL_PENALTY
from envs import Recording, make_world, rollout
from terrain import Heightfield
from walk_engine import GaitParams, WalkCommand, WalkEngine, params_for



@dataclass(frozen=True)
class WalkResult:
    """Outcome of one walking rollout.

    Attributes:
        speed_cm_s: forward torso displacement / nominal duration [cm/s].
        fitness: ``speed_cm_s - 15 * fell``.
        fell: whether the episode ended in a fall (or an unstable simulation).
        fall_reason: ``"torso_low"``, ``"tilt"``, ``"unstable"`` or None.
        fall_time_s: time of the fall [s] or None.
        drift_m: lateral displacement |Δy| of the torso [m].
        distance_m: forward displacement Δx of the torso [m] (until the fall, if any).
        seconds: nominal duration [s].
        steps: control steps recorded.
    """

    speed_cm_s: float
    fitness: float
    fell: bool
    fall_reason: str | None
    fall_time_s: float | None
    drift_m: float
    distance_m: float
    seconds: float
    steps: int

    def to_dict(self) -> dict:
        return asdict(self)


def walk_fitness(rec: Recording, seconds: float | None = None) -> WalkResult:
    """The paper's reward and diagnostics of a recording.

    Args:
        rec: a walking rollout with ``gt.base`` columns (torso origin, world frame).
        seconds: nominal duration [s] (default: ``rec.meta["seconds"]``, else 7.5).

    Returns:
        :class:`WalkResult`; always finite (a non-finite position counts as a fall with 0 m).

    Raises:
        ValueError: the recording has no ``gt.base`` columns or a non-positive duration.
    """
    if not rec.has("gt.base"):
        raise ValueError("recording has no ground-truth torso positions (gt.base.*): cannot compute the fitness")
    T = float(seconds if seconds is not None else rec.meta.get("seconds", EPISODE_SECONDS))
    if not (T > 0 and math.isfinite(T)):
        raise ValueError(f"nominal duration must be positive, got {T}")
    base = rec.group("gt.base")
    fell = bool(rec.meta.get("fell", False))
    reason = rec.meta.get("fall_reason")
    ok = np.all(np.isfinite(base), axis=1)
    if not ok.any():
        dx = dy = 0.0
        fell, reason = True, reason or "unstable"
    else:
        last = int(np.flatnonzero(ok)[-1])
        dx = float(base[last, 0] - base[0, 0])
        dy = float(base[last, 1] - base[0, 1])
    speed = 100.0 * dx / T
    return WalkResult(speed_cm_s=speed, fitness=speed - FALL_PENALTY * float(fell), fell=fell,
                      fall_reason=reason if fell else None,
                      fall_time_s=rec.meta.get("fall_time") if fell else None,
                      drift_m=abs(dy), distance_m=dx, seconds=T, steps=len(rec))


def walk_meta(params: GaitParams, command: WalkCommand | None = None) -> dict:
    """The metadata a walk recording carries: the gait, the command, the controller."""
    cmd = command or WalkCommand()
    return {"params": params.to_dict(), "command": {"vx": cmd.vx, "vy": cmd.vy, "wz": cmd.wz},
            "controller": "walk_engine.WalkEngine"}


def run_walk(params: GaitParams | None = None, world: str = "sim", seed: int = 0,
             seconds: float = EPISODE_SECONDS, profile="real", terrain: str | Heightfield | None = None,
             command: WalkCommand | None = None, env=None, robot=None,
             stochasticity: float = 0.0) -> tuple[Recording, WalkResult]:
    """One walking episode of the ZMP engine with ``params`` and its fitness.

    Args:
        params: gait parameters (default θ0).
        world: ``"sim"`` (MuJoCo) or ``"real"`` (PyBullet); ignored if ``env`` is given.
        seed: episode seed (real world: terrain, effects, noise).
        seconds: nominal duration [s].
        profile: real-world effect profile (name, dict or ``envs.RealProfile``).
        terrain: None (sim: flat; real: the profile's lumpy field), ``"flat"``, ``"lumpy"`` (real
            only) or a :class:`terrain.Heightfield`.
        command: walking command (default: forward at the gait's speed).
        env: an existing world (or wrapper, e.g. ``sgat.GroundedEnv``) to reuse.
        robot: the ``robots.RobotModel`` of a new world (default the NAO); params default to its θ0.
        stochasticity: the real world's per-step randomness level (``envs.effects.Stochasticity``).

    Returns:
        (recording with ``meta["params"]`` and ``meta["command"]``, :class:`WalkResult`). A fall
        is data: it gives the -15 penalty, never an exception.

    Raises:
        ValueError: unknown world/profile/terrain, non-positive seconds, params not GaitParams.
    """
    if env is not None:
        robot = env.unwrapped.robot
    params = params or (params_for(robot)() if robot is not None else GaitParams())
    if not isinstance(params, GaitParams):
        raise ValueError(f"params must be a GaitParams, got {type(params).__name__}")
    own = env is None
    if own:
        kw = {} if robot is None else {"robot": robot}
        if world == "real":
            kw.update(profile=profile, terrain="lumpy" if terrain is None else terrain, stochasticity=stochasticity)
        elif stochasticity:
            raise ValueError("stochasticity is the real world's (use world 'real')")
        if world == "sim":
            if terrain == "lumpy":
                raise ValueError("terrain 'lumpy' (a fresh field per seed) is for the real world; pass a Heightfield")
            kw.update(terrain=terrain)
        env = make_world(world, **kw)
    try:
        base = env.unwrapped
        engine = WalkEngine(base.robot, params, command, dt=base.control_dt)
        rec = rollout(env, engine, seed=seed, seconds=seconds, meta=walk_meta(params, command))
    finally:
        if own:
            env.close()
    return rec, walk_fitness(rec, seconds)
