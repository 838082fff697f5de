"""The gymnasium MuJoCo tasks and their "real" variants (SGAT paper §IV.B).

* :class:`GaussianActionNoise` -- the NoisySim/NoisyReal actuator: zero-mean Gaussian noise with
  σ = ``sigma`` × half the action range, added to a **copy** of the commanded action and clipped
  to the bounds. The agent's (and any logger's) array is never modified in place -- the trap
  that silently turned logged actions into noisy ones in the GARAT code
  (``NoisyRealEnv.action`` in ``rl_gat/gat.py``, Desai et al., NeurIPS 2020). The noise generator is seeded by ``reset(seed=s)`` and keeps
  running across later unseeded resets (a vectorised trainer resets with no seed after every
  episode; re-seeding there would replay the same noise sequence in every episode).
* :func:`scale_body_masses` -- heavier bodies: ``model.body_mass`` and ``model.body_inertia``
  scaled after loading (``mjcf settotalmass`` is deprecated in MuJoCo >= 3), then
  ``mujoco.mj_setConst`` recomputes the derived constants (subtree masses, inverse weights).
* :func:`make_env` -- the sim, the noisy sim (ANE) and the "real" variants of a task.
* :func:`set_state_from_obs` -- put an env into the state an observation describes (for the
  one-step transition error of the GARAT appendix, Desai et al., NeurIPS 2020).
"""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np

from experiments.gym.config import TASKS, canonical_env

_NOISE_TAG = 0x6E015E


class GaussianActionNoise(gym.Wrapper):
    """Gaussian action noise on a copy of the action, clipped to the action bounds.

    ``a_applied = clip(a + ε, low, high)``, ``ε ~ N(0, (sigma · (high - low) / 2)²)`` per entry.

    Args:
        env: a gymnasium env with a Box action space.
        sigma: noise standard deviation as a share of the action half-range (>= 0).
        ctrl_cost_weight: for gymnasium MuJoCo envs whose reward holds ``info["reward_ctrl"] =
            -w·|a_applied|²``: recompute that term on the commanded action, so the reward is
            R(a_t, s_{t+1}) of the agent's action as in the paper (None: leave the reward alone).
        seed: seed of the noise generator until the first ``reset(seed=...)``.

    ``info`` of every step holds ``commanded_action`` (a copy of what the agent sent) and
    ``applied_action`` (what the inner env got).

    Raises:
        ValueError: negative or non-finite sigma, non-Box action space.
    """

    def __init__(self, env: gym.Env, sigma: float, *, ctrl_cost_weight: float | None = None, seed: int | None = None):
        super().__init__(env)
        if not isinstance(env.action_space, gym.spaces.Box):
            raise ValueError("GaussianActionNoise needs a Box action space")
        sigma = float(sigma)
        if not np.isfinite(sigma) or sigma < 0:
            raise ValueError(f"noise sigma must be a finite share >= 0 of the action half-range, got {sigma}")
        self.sigma = sigma
        self.low = np.asarray(env.action_space.low, dtype=np.float64)
        self.high = np.asarray(env.action_space.high, dtype=np.float64)
        self.std = sigma * (self.high - self.low) / 2.0
        self.ctrl_cost_weight = ctrl_cost_weight
        self.rng = np.random.default_rng(None if seed is None else np.random.SeedSequence([int(seed), _NOISE_TAG]))

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        if seed is not None:
            self.rng = np.random.default_rng(np.random.SeedSequence([int(seed), _NOISE_TAG]))
        return self.env.reset(seed=seed, options=options)

    def perturb(self, action) -> np.ndarray:
        """The applied action for ``action`` (a new float64 array; ``action`` is untouched)."""
        out = np.array(action, dtype=np.float64)  # copy, never a view of the caller's array
        if out.shape != self.low.shape:
            raise ValueError(f"action must have shape {self.low.shape}, got {out.shape}")
        if self.sigma > 0:
            out = out + self.rng.standard_normal(out.shape) * self.std
        return np.clip(out, self.low, self.high)

    def step(self, action):
        commanded = np.array(action, dtype=np.float64)
        applied = self.perturb(commanded)
        obs, reward, terminated, truncated, info = self.env.step(applied)
        info = dict(info)
        info["commanded_action"] = commanded
        info["applied_action"] = applied
        if self.ctrl_cost_weight is not None and "reward_ctrl" in info:
            agent_ctrl = -self.ctrl_cost_weight * float(np.sum(np.clip(commanded, self.low, self.high) ** 2))
            reward = float(reward) - float(info["reward_ctrl"]) + agent_ctrl
            info["reward_ctrl"] = agent_ctrl
        return obs, reward, terminated, truncated, info


def body_names(env: gym.Env) -> list[str]:
    """Names of the bodies of a MuJoCo env's model, index order (``world`` first)."""
    import mujoco  # lazy: mujoco (only the MuJoCo tasks need it)

    m = env.unwrapped.model
    return [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, i) for i in range(m.nbody)]


def scale_body_masses(env: gym.Env, factor: float, bodies: list[str] | None = None) -> dict:
    """Multiply the mass and the rotational inertia of ``bodies`` (None: all) by ``factor``.

    Works on the env's own compiled model (``env.unwrapped.model``), then calls
    ``mujoco.mj_setConst`` so derived constants follow.

    Returns:
        ``{"bodies": [...], "factor": f, "mass_before": [...], "mass_after": [...],
        "total_before": kg, "total_after": kg}``.

    Raises:
        ValueError: non-positive factor or an unknown body name.
    """
    import mujoco  # lazy: mujoco (only the MuJoCo tasks need it)

    factor = float(factor)
    if not np.isfinite(factor) or factor <= 0:
        raise ValueError(f"mass factor must be positive, got {factor}")
    base = env.unwrapped
    m = base.model
    names = body_names(env)
    if bodies is None:
        idx = list(range(1, m.nbody))  # body 0 is the world
    else:
        unknown = [b for b in bodies if b not in names]
        if unknown:
            raise ValueError(f"unknown body {unknown[0]!r}; the model has {', '.join(names)}")
        idx = [names.index(b) for b in bodies]
    before = m.body_mass[idx].copy()
    total_before = float(m.body_mass.sum())
    m.body_mass[idx] *= factor
    m.body_inertia[idx] *= factor
    mujoco.mj_setConst(m, base.data)
    return {"bodies": [names[i] for i in idx], "factor": factor, "mass_before": before.tolist(),
            "mass_after": m.body_mass[idx].tolist(), "total_before": total_before,
            "total_after": float(m.body_mass.sum())}


def _route_mujoco_warnings() -> None:
    """Send MuJoCo's own warnings (``mju_warning``) to Python's ``warnings`` instead of its default
    handler, which appends them to ``MUJOCO_LOG.TXT`` in the working directory (gymnasium's
    HalfCheetah XML uses the deprecated ``settotalmass`` compiler attribute). Installed once per
    process, and only where no handler is installed yet (``mujoco.set_mju_user_warning``)."""
    import mujoco  # lazy: mujoco (only the MuJoCo tasks need it)

    if mujoco.get_mju_user_warning() is None:
        mujoco.set_mju_user_warning(lambda msg: warnings.warn(f"MuJoCo: {msg}", RuntimeWarning, stacklevel=2))


def make_env(task: str, *, heavy: bool = False, noise: float = 0.0, pole_factor: float = 10.0,
             mass_factor: float = 20.0 / 14.0, seed: int | None = None) -> gym.Env:
    """A task's env: the sim (defaults), a noisy sim (``noise`` > 0, the ANE baseline), or a
    "real" variant (``heavy``: the mass change of Sim-to-NoisyReal; ``noise``: the actuator
    noise of both NoisySim and NoisyReal).

    Args:
        task: ``"InvertedPendulum"`` or ``"HalfCheetah"`` (aliases: see ``canonical_env``).
        heavy: apply the mass change (InvertedPendulum: pole × ``pole_factor``; HalfCheetah:
            every body × ``mass_factor``).
        noise: σ of the action noise, share of the action half-range (0: no noise wrapper).

    The applied mass change is stored as ``env.unwrapped.sgat_mass_change`` (the
    :func:`scale_body_masses` report, or None).

    Raises:
        ValueError: unknown task, invalid factor or noise.
    """
    task = canonical_env(task)
    _route_mujoco_warnings()
    env = gym.make(TASKS[task]["env_id"])
    change = None
    if heavy:
        if task == "InvertedPendulum":
            change = scale_body_masses(env, pole_factor, ["pole"])
        else:
            change = scale_body_masses(env, mass_factor)
    env.unwrapped.sgat_mass_change = change
    if noise and noise > 0:
        env = GaussianActionNoise(env, noise, ctrl_cost_weight=TASKS[task]["ctrl_cost_weight"], seed=seed)
    elif noise < 0:
        raise ValueError(f"noise must be >= 0, got {noise}")
    return env


def set_state_from_obs(env: gym.Env, obs: np.ndarray) -> None:
    """Set a gymnasium MuJoCo env's (qpos, qvel) to what ``obs`` describes.

    InvertedPendulum observes ``[qpos, qvel]``; HalfCheetah ``[qpos[1:], qvel]`` (the x position is
    left out and does not affect the dynamics, so it is set to 0).

    Raises:
        ValueError: an observation of the wrong size.
    """
    base = env.unwrapped
    nq, nv = base.model.nq, base.model.nv
    obs = np.asarray(obs, dtype=np.float64)
    skip = 1 if getattr(base, "_exclude_current_positions_from_observation", False) else 0
    if obs.shape != (nq - skip + nv,):
        raise ValueError(f"observation of size {obs.shape} does not describe a state of this env (nq={nq}, nv={nv})")
    qpos = np.concatenate([np.zeros(skip), obs[:nq - skip]])
    base.set_state(qpos, obs[nq - skip:])
