"""Run a controller in a world and keep what happened as a :class:`envs.recording.Recording`."""

from __future__ import annotations

import math
from typing import Any, Callable, Protocol

import numpy as np

from common.defaults import EPISODE_SECONDS
from envs.recording import Recording
from robots import RobotModel


class Controller(Protocol):
    """What :func:`rollout` drives: ``reset(obs, info)`` (optional) and ``step(obs) -> action``.

    A plain callable ``obs -> action`` works too. Actions are joint targets [rad], shape (23,).
    """

    def step(self, obs: np.ndarray) -> np.ndarray: ...


class HoldPose:
    """Hold a named pose of the robot (default: the walking crouch)."""

    def __init__(self, robot: RobotModel, pose: str = "crouch"):
        self.target = robot.pose(pose, actuated=True)

    def step(self, obs: np.ndarray) -> np.ndarray:
        return self.target


class CommandLog:
    """Replay a fixed command log, shape (N, 23); after its end the last command is held."""

    def __init__(self, commands: np.ndarray):
        self.commands = np.asarray(commands, dtype=np.float64)
        self.k = 0

    def reset(self, obs=None, info=None) -> None:
        self.k = 0

    def step(self, obs: np.ndarray) -> np.ndarray:
        a = self.commands[min(self.k, len(self.commands) - 1)]
        self.k += 1
        return a


def rollout(env, controller: Controller | Callable[[np.ndarray], Any], seed: int | None = 0,
            seconds: float = EPISODE_SECONDS, options: dict | None = None, meta: dict | None = None) -> Recording:
    """Reset ``env`` with ``seed`` and run ``controller`` for ``seconds`` (or until the episode ends).

    Args:
        env: an :class:`envs.HumanoidEnv` or a wrapper of one (e.g. ``sgat.GroundedEnv``); the applied
            action is read from ``info["applied_action"]``.
        controller: see :class:`Controller`.
        seed: episode seed (terrain, effects, noise in the real world).
        seconds: nominal duration [s]; ``round(seconds / control_dt)`` steps at most.
        options: passed to ``env.reset``.
        meta: extra metadata merged into the recording's.

    Returns:
        A validated :class:`Recording` with observation, command, applied-command and ground-truth
        columns; ``meta`` holds ``fell``, ``fall_time``, ``fall_reason`` and the world's settings.

    Raises:
        ValueError: ``seconds`` not positive; whatever the env raises for a bad action.
    """
    if not (seconds > 0 and math.isfinite(seconds)):
        raise ValueError(f"seconds must be positive, got {seconds}")
    base = env.unwrapped
    robot = base.robot
    layout = base.layout
    n = int(round(seconds / base.control_dt))
    obs, info = env.reset(seed=seed, options=options)
    if hasattr(controller, "reset"):
        controller.reset(obs, info)
    step = controller.step if hasattr(controller, "step") else controller
    na = len(robot.actuated_joint_names)
    O = np.empty((n, layout.size))
    C = np.empty((n, na))
    A = np.empty((n, na))
    G = np.full((n, 22), np.nan)  # base 3, quat 4, vel 3, angvel 3, com 3, cop 3, + 3 spare
    fell, reason, fall_time = False, None, None
    k = 0
    for k in range(n):
        O[k] = obs
        G[k, :19] = gt_row(info)
        a = np.asarray(step(obs), dtype=np.float64)
        C[k] = a
        obs, _, terminated, truncated, info = env.step(a)
        A[k] = info.get("applied_action", a)
        if terminated:
            fell, reason, fall_time = True, info.get("fall_reason"), (k + 1) * base.control_dt
            break
        if truncated:
            break
    return assemble_recording(base, O, C, A, G, k + 1, seed=seed, seconds=seconds, fell=fell, reason=reason,
                              fall_time=fall_time, meta=meta)


#: Ground-truth columns of a recording, in the order of :func:`rollout`'s ``G`` array (19 used of 22).
GT_COLUMNS = ("gt.base.x", "gt.base.y", "gt.base.z", "gt.quat.w", "gt.quat.x", "gt.quat.y", "gt.quat.z",
              "gt.vel.x", "gt.vel.y", "gt.vel.z", "gt.angvel.x", "gt.angvel.y", "gt.angvel.z",
              "gt.com.x", "gt.com.y", "gt.com.z", "gt.cop.x", "gt.cop.y", "gt.cop.z")


def gt_row(info: dict) -> np.ndarray:
    """The ground-truth row (19,) of a step's ``info``, in :data:`GT_COLUMNS` order (the CoP NaN
    without foot contact)."""
    return np.concatenate([info["base_pos"], info["base_quat"], info["base_linvel"], info["base_angvel"],
                           info["com"], info["cop_world"] if info["cop_valid"] else np.full(3, np.nan)])


def assemble_recording(base, O: np.ndarray, C: np.ndarray, A: np.ndarray, G: np.ndarray, m: int, *, seed,
                       seconds: float, fell: bool, reason: str | None, fall_time: float | None,
                       meta: dict | None = None, terrain=...) -> Recording:
    """The validated :class:`Recording` of the first ``m`` rows of one episode's arrays.

    Args:
        base: the unwrapped world (robot, layout, time steps, terrain, profile).
        O, C, A, G: observations (N, layout.size), commands and applied commands (N, 23), ground
            truth (N, >= 19) in :data:`GT_COLUMNS` order; rows >= ``m`` are ignored.
        m: rows recorded; seed, seconds, fell, reason, fall_time, meta: the episode's metadata.
        terrain: the episode's heightfield (None: flat) if not ``base.terrain``.

    Used by :func:`rollout` and by batched rollouts (``experiments.runtime.batch``), so both write the same
    recording bit for bit.
    """
    robot = base.robot
    terrain = base.terrain if terrain is ... else terrain
    md = {
        "schema_version": 1, "robot": robot.name, "world": getattr(base, "world", "unknown"),
        "control_dt": base.control_dt, "physics_dt": base.physics_dt, "seed": seed, "seconds": seconds,
        "fixed_base": base.fixed_base,
        "terrain": None if terrain is None else terrain.to_dict(),
        "fell": fell, "fall_time": fall_time, "fall_reason": reason,
    }
    if hasattr(base, "profile"):
        md["profile"] = base.profile.name
        md["effects"] = base.effects.to_dict()
    md.update(meta or {})
    cols = {"t": np.arange(m) * base.control_dt}
    cols.update({nm: O[:m, i].copy() for i, nm in enumerate(base.layout.names)})
    cols.update({f"cmd.{nm}": C[:m, i].copy() for i, nm in enumerate(robot.actuated_joint_names)})
    cols.update({f"app.{nm}": A[:m, i].copy() for i, nm in enumerate(robot.actuated_joint_names)})
    cols.update({nm: G[:m, i].copy() for i, nm in enumerate(GT_COLUMNS)})
    rec = Recording(cols, md)
    rec.validate()
    return rec
