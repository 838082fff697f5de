"""The action transformer and the grounded environment (SGAT paper §III, Algorithm 1).

``g(s_t, a_t) = f_sim^-1(s_t, ŝ_{t+1})`` with ``ŝ_{t+1} = s_t + Δŝ``, ``Δŝ ~ f_real(s_t, a_t)``
(SGAT samples; GAT takes the mean). The transformed action is blended with the agent's,
``ã = (1 - α) a + α g(s, a)`` (α = 1 is the paper's formulation), clipped to the action bounds.
Before the first fit the transformer is the identity.

What is grounded is a :class:`GroundingSpec`: which observation entries form the grounding state
and which action entries are transformed. For the NAO the default is what a NAO measures of its
legs -- the 12 leg encoder angles and 12 leg joint velocities -- and the 11 actuated leg joint
targets; arms and head pass through unchanged (they hardly affect the walk, and grounding them
would triple the model's output size). Alternatives are ``"legs+imu"`` (adds torso gyro and
roll/pitch) and a history of k frames.
"""

from __future__ import annotations

import json
import os
from collections import deque
from dataclasses import dataclass

import gymnasium as gym
import numpy as np

from sgat.models import ForwardModel, InverseModel

METHODS = ("sgat", "gat")


@dataclass(frozen=True, eq=False)
class GroundingSpec:
    """Which observation entries are the grounding state and which action entries are grounded.

    Attributes:
        state_index: indices into the observation vector, shape (S,).
        action_index: indices into the action vector, shape (A,).
        action_low, action_high: bounds of the grounded actions, shape (A,) (transformed actions
            are clipped to them).
        history: frames k of state history the models see.
        state_names, action_names: labels for reports.
    """

    state_index: np.ndarray
    action_index: np.ndarray
    action_low: np.ndarray
    action_high: np.ndarray
    history: int = 1
    state_names: tuple[str, ...] = ()
    action_names: tuple[str, ...] = ()
    name: str = "custom"

    @property
    def state_dim(self) -> int:
        return len(self.state_index)

    @property
    def action_dim(self) -> int:
        return len(self.action_index)

    @classmethod
    def for_nao(cls, env, variant: str = "legs", history: int = 1) -> "GroundingSpec":
        """Default NAO grounding: ``"legs"`` (leg q, dq; leg targets) or ``"legs+imu"`` (plus gyro,
        roll, pitch). ``env`` is an ``envs.NaoEnv`` (or wrapper).

        Raises:
            ValueError: unknown variant or history < 1.
        """
        base = env.unwrapped
        robot, layout = base.robot, base.layout
        if variant not in ("legs", "legs+imu"):
            raise ValueError(f"unknown grounding state {variant!r}; choose 'legs' or 'legs+imu'")
        if history < 1:
            raise ValueError(f"history must be >= 1, got {history}")
        legs = robot.groups["legs"]
        names = [f"q.{j}" for j in legs] + [f"dq.{j}" for j in legs]
        if variant == "legs+imu":
            names += ["gyro.x", "gyro.y", "gyro.z", "angle.roll", "angle.pitch"]
        state_index = np.array([layout.names.index(n) for n in names])
        act_names = [j for j in robot.actuated_joint_names if j in legs]
        action_index = np.array([robot.actuated_joint_names.index(j) for j in act_names])
        lo = base.action_space.low[action_index]
        hi = base.action_space.high[action_index]
        return cls(state_index, action_index, lo, hi, history, tuple(names), tuple(act_names), f"nao-{variant}")

    @classmethod
    def full(cls, env, history: int = 1) -> "GroundingSpec":
        """Ground the whole observation and action of a Box-space gymnasium env."""
        n_obs = env.observation_space.shape[0]
        n_act = env.action_space.shape[0]
        return cls(np.arange(n_obs), np.arange(n_act), env.action_space.low.astype(float),
                   env.action_space.high.astype(float), history, name="full")

    def to_dict(self) -> dict:
        return {"state_index": self.state_index.tolist(), "action_index": self.action_index.tolist(),
                "action_low": self.action_low.tolist(), "action_high": self.action_high.tolist(),
                "history": self.history, "state_names": list(self.state_names),
                "action_names": list(self.action_names), "name": self.name}

    @classmethod
    def from_dict(cls, d: dict) -> "GroundingSpec":
        return cls(np.array(d["state_index"]), np.array(d["action_index"]), np.array(d["action_low"]),
                   np.array(d["action_high"]), int(d["history"]), tuple(d["state_names"]),
                   tuple(d["action_names"]), d.get("name", "custom"))

    def states(self, obs: np.ndarray) -> np.ndarray:
        """Grounding states of observations (..., n_obs) -> (..., S)."""
        return np.asarray(obs)[..., self.state_index]

    def stack_history(self, S: np.ndarray) -> np.ndarray:
        """(N, S) states of one trajectory -> (N, k*S) histories, oldest first, padded with s_0."""
        k = self.history
        if k == 1:
            return S
        idx = np.clip(np.arange(len(S))[:, None] + np.arange(-k + 1, 1)[None], 0, None)
        return S[idx].reshape(len(S), -1)


class ActionTransformer:
    """``(state history, action) -> grounded action``, NumPy inference.

    Args:
        spec: the :class:`GroundingSpec`.
        forward, inverse: fitted models; both None means the identity (before the first fit).
        method: ``"sgat"`` (sample the forward model) or ``"gat"`` (its mean).
        alpha: blend ã = (1 - α) a + α g(s, a), in [0, 1].
        seed: seed of the sampling generator (re-seeded by :meth:`reset`).

    Raises:
        ValueError: unknown method, α outside [0, 1], only one model given, or models whose
            sizes do not match the spec.
    """

    def __init__(self, spec: GroundingSpec, forward: ForwardModel | None = None, inverse: InverseModel | None = None,
                 *, method: str = "sgat", alpha: float = 1.0, seed: int = 0):
        if method not in METHODS:
            raise ValueError(f"unknown grounding method {method!r}; choose from {', '.join(METHODS)}")
        if not 0.0 <= alpha <= 1.0:
            raise ValueError(f"alpha must be in [0, 1], got {alpha}")
        if (forward is None) != (inverse is None):
            raise ValueError("give both a forward and an inverse model, or neither (identity)")
        if forward is not None:
            S, A, k = spec.state_dim, spec.action_dim, spec.history
            if (forward.state_dim, forward.action_dim, forward.history) != (S, A, k) or \
                    (inverse.state_dim, inverse.action_dim, inverse.history) != (S, A, k):
                raise ValueError(f"model sizes do not match the grounding spec (S={S}, A={A}, k={k})")
        self.spec, self.forward, self.inverse = spec, forward, inverse
        self.method, self.alpha, self.seed = method, float(alpha), seed
        self.rng = np.random.default_rng(seed)

    @property
    def is_identity(self) -> bool:
        return self.forward is None

    def reset(self, seed: int | None = None) -> None:
        """Re-seed the sampling generator (an episode's seed makes grounded rollouts repeatable)."""
        self.rng = np.random.default_rng(self.seed if seed is None else np.random.SeedSequence([int(seed), 0x5a7]))

    def transform(self, hist: np.ndarray, a: np.ndarray) -> np.ndarray:
        """Grounded actions for state histories ``hist`` (..., k*S) and actions ``a`` (..., A)."""
        a = np.asarray(a, dtype=np.float64)
        if self.forward is None:
            return a.copy()
        hist = np.asarray(hist, dtype=np.float64)
        x = np.concatenate([hist, a], axis=-1)
        if self.method == "sgat" and self.forward.stochastic:
            ds = self.forward.sample(x, self.rng)
        else:
            ds = self.forward.predict(x)[0]
        g = self.inverse.predict(np.concatenate([hist, ds], axis=-1))
        out = (1.0 - self.alpha) * a + self.alpha * g if self.alpha < 1.0 else g
        return np.clip(out, self.spec.action_low, self.spec.action_high)

    # -- persistence ---------------------------------------------------------------------------
    def save(self, directory: str | os.PathLike) -> str:
        """Write ``forward.pt``, ``inverse.pt`` and ``transformer.json`` into ``directory``."""
        directory = os.fspath(directory)
        os.makedirs(directory, exist_ok=True)
        if self.forward is not None:
            self.forward.save(os.path.join(directory, "forward.pt"))
            self.inverse.save(os.path.join(directory, "inverse.pt"))
        meta = {"method": self.method, "alpha": self.alpha, "seed": self.seed, "identity": self.is_identity,
                "spec": self.spec.to_dict()}
        tmp = os.path.join(directory, f"transformer.json.{os.getpid()}.tmp")
        with open(tmp, "w") as f:
            json.dump(meta, f, indent=1)
        os.replace(tmp, os.path.join(directory, "transformer.json"))
        return directory

    @classmethod
    def load(cls, directory: str | os.PathLike) -> "ActionTransformer":
        """Load what :meth:`save` wrote.

        Raises:
            FileNotFoundError: missing files. ModelFileError: corrupted or mismatched weights.
        """
        directory = os.fspath(directory)
        path = os.path.join(directory, "transformer.json")
        if not os.path.exists(path):
            raise FileNotFoundError(f"no transformer.json in {directory!r}")
        with open(path) as f:
            meta = json.load(f)
        spec = GroundingSpec.from_dict(meta["spec"])
        fwd = inv = None
        if not meta["identity"]:
            S, A, k = spec.state_dim, spec.action_dim, spec.history
            fwd = ForwardModel.load(os.path.join(directory, "forward.pt"), expect_in=k * S + A, expect_out=S)
            inv = InverseModel.load(os.path.join(directory, "inverse.pt"), expect_in=(k + 1) * S, expect_out=A)
        return cls(spec, fwd, inv, method=meta["method"], alpha=meta["alpha"], seed=meta["seed"])


class GroundedEnv(gym.Wrapper):
    """The grounded sim: every action passes through an :class:`ActionTransformer` first.

    The agent's action is what the reward and the recording see as the command
    (``info["commanded_action"]``); the transformed one is applied and reported as
    ``info["applied_action"]`` (after the inner env's own clipping, if it reports one).

    Args:
        env: any gymnasium env with Box spaces (the NAO sim, or a gymnasium MuJoCo task).
        transformer: the :class:`ActionTransformer`.
        ctrl_cost_weight: for envs whose reward has a control cost ``-w * |a|^2`` reported as
            ``info["reward_ctrl"]`` (gymnasium MuJoCo), recompute that term on the agent's action
            (``reference/grounding.md`` §4: control cost uses a, not ã).
    """

    def __init__(self, env: gym.Env, transformer: ActionTransformer, *, ctrl_cost_weight: float | None = None):
        super().__init__(env)
        self.transformer = transformer
        self.ctrl_cost_weight = ctrl_cost_weight
        self._hist: deque = deque(maxlen=transformer.spec.history)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        self.transformer.reset(seed)
        s = self.transformer.spec.states(obs)
        self._hist.clear()
        self._hist.extend([s] * self.transformer.spec.history)
        return obs, info

    def step(self, action):
        a = np.array(action, dtype=np.float64)  # a copy: the agent's array is never modified
        spec = self.transformer.spec
        applied = a.copy()
        if not self.transformer.is_identity:
            if a.shape != self.env.action_space.shape:
                raise ValueError(f"action must have shape {self.env.action_space.shape}, got {a.shape}")
            if not np.all(np.isfinite(a)):
                raise ValueError("action contains NaN or infinite values")
            hist = np.concatenate(list(self._hist))
            applied[spec.action_index] = self.transformer.transform(hist, a[spec.action_index])
        obs, reward, terminated, truncated, info = self.env.step(applied)
        info = dict(info)
        info.setdefault("applied_action", applied)
        info["commanded_action"] = a
        if self.ctrl_cost_weight is not None and "reward_ctrl" in info:
            agent_ctrl = -self.ctrl_cost_weight * float(np.sum(a ** 2))
            reward = reward - info["reward_ctrl"] + agent_ctrl
            info["reward_ctrl"] = agent_ctrl
        self._hist.append(spec.states(obs))
        return obs, reward, terminated, truncated, info
