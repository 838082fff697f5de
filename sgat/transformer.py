"""The action transformer and the grounded environment (SGAT paper §III, Algorithm 1).

``g(s_t, a_t) = f_sim^-1(s_t, ŝ_{t+1})`` with ``ŝ_{t+1} = s_t + Δŝ``, ``Δŝ ~ f_real(s_t, a_t)``
(SGAT samples; GAT takes the mean). The transformed action is blended with the agent's,
``ã = (1 - α) a + α g(s, a)`` (α = 1 is the paper's formulation), clipped to the action bounds.
Before the first fit the transformer is the identity.

What is grounded is a :class:`GroundingSpec`: which observation entries form the grounding state
and which action entries are transformed. For the NAO the default is what a NAO measures of its
legs -- the 12 leg encoder angles and 12 leg joint velocities, over a history of k frames -- and the
11 actuated leg joint targets; arms and head pass through unchanged (they hardly affect the walk,
and grounding them would triple the model's output size).
"""

from __future__ import annotations

import json
import os
from collections import deque
from dataclasses import dataclass

import gymnasium as gym
import numpy as np

from sgat.models import ForwardModel, InverseModel, ModelFileError
from common.files import atomic_write_text

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
    def from_names(cls, obs_names, state_names, action_names, grounded, low, high, history: int = 1,
                   name: str = "custom") -> "GroundingSpec":
        """A spec from names: ``state_names`` picked out of the observation's ``obs_names``, and the
        ``grounded`` actions out of ``action_names`` (``low``/``high``: bounds of the whole action).

        Raises:
            ValueError: a name that is not in the observation or action, or history < 1.
        """
        if history < 1:
            raise ValueError(f"history must be >= 1, got {history}")
        obs_names, action_names = list(obs_names), list(action_names)
        missing = [n for n in state_names if n not in obs_names] + [n for n in grounded if n not in action_names]
        if missing:
            raise ValueError(f"not in the observation/action: {', '.join(missing)}")
        state_index = np.array([obs_names.index(n) for n in state_names])
        action_index = np.array([action_names.index(n) for n in grounded])
        return cls(state_index, action_index, np.asarray(low, dtype=float)[action_index],
                   np.asarray(high, dtype=float)[action_index], history, tuple(state_names), tuple(grounded), name)

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


def _members(m) -> list:
    return [] if m is None else list(m) if isinstance(m, (list, tuple)) else [m]


class ActionTransformer:
    """``(state history, action) -> grounded action``, NumPy inference (SGAT paper §III, Algorithm 1).

    ``g(s_t, a_t) = f_sim^-1(s_t, ŝ_{t+1} − s_t)`` with ``ŝ_{t+1} − s_t ~ f_real(s_t, a_t)`` (SGAT
    samples the forward model; GAT takes its mean), blended with the agent's action,
    ``ã = (1 − α) a + α g(s, a)``, and clipped to the grounded actions' bounds.

    Args:
        spec: the :class:`GroundingSpec`.
        forward, inverse: fitted models, or equal-length lists of them (an ensemble: member i is the
            pair ``(forward[i], inverse[i])``); both None means the identity (before the first fit).
        method: ``"sgat"`` (sample the forward model) or ``"gat"`` (its mean).
        alpha: blend α in [0, 1]; required when models are given (the paper's formula is α = 1; the
            GAT/GARAT code uses 0.5).
        seed: seed of the sampling generator (re-seeded by :meth:`reset`).

    An ensemble expresses model uncertainty the way PETS's trajectory sampling does (Chua et al.,
    NeurIPS 2018, §4.2 "TS∞"): SGAT draws one member per episode at :meth:`reset` and keeps it for
    the whole episode, so a grounded sim is one plausible fit of the real data, not one arbitrary
    fit; GAT (deterministic) averages the members' predictions.

    **Delay** d (inverse models with ``commands`` d, ``GroundingConfig.delay``; 0: the paper): for a
    sim whose actuators answer a command d control steps late, a_t first shows in s_{t+d+1}. The
    forward models then predict Δŝ = ŝ_{t+d+1} − s_t from the state history, the agent's d previous
    commands (``past``) and a_t, and the inverse models answer it given the d actions the sim was sent
    before (``sent``: the transformer's own earlier outputs, which callers keep per episode):
    g = f_sim^-1(s_t, â_{t-d}, ..., â_{t-1}, ŝ_{t+d+1} − s_t).

    Raises:
        ValueError: unknown method, α missing or outside [0, 1], only one kind of model given,
            ensembles of different sizes, models whose sizes do not match the spec, members that
            disagree on their mixture components or delay, or a delay the forward models do not see.
    """

    def __init__(self, spec: GroundingSpec, forward=None, inverse=None, *, method: str = "sgat",
                 alpha: float | None = None, seed: int = 0):
        if method not in METHODS:
            raise ValueError(f"unknown grounding method {method!r}; choose from {', '.join(METHODS)}")
        fwds, invs = _members(forward), _members(inverse)
        if bool(fwds) != bool(invs) or len(fwds) != len(invs):
            raise ValueError("give forward and inverse models in equal numbers (ensemble members), or neither (identity)")
        if fwds and alpha is None:
            raise ValueError("alpha (the blend of the agent's and the grounded action) is required with fitted models")
        alpha = 1.0 if alpha is None else alpha
        if not 0.0 <= alpha <= 1.0:
            raise ValueError(f"alpha must be in [0, 1], got {alpha}")
        S, A, k = spec.state_dim, spec.action_dim, spec.history
        for f, i in zip(fwds, invs):
            if (f.state_dim, f.action_dim, f.history) != (S, A, k) or (i.state_dim, i.action_dim, i.history) != (S, A, k):
                raise ValueError(f"model sizes do not match the grounding spec (S={S}, A={A}, k={k})")
        if len({f.components for f in fwds}) > 1:
            raise ValueError("ensemble members disagree on the number of mixture components")
        if len({f.commands for f in fwds}) > 1 or len({i.commands for i in invs}) > 1:
            raise ValueError("ensemble members disagree on the delay their models bridge")
        delay = invs[0].commands if invs else 0
        if delay and fwds[0].commands != delay:
            raise ValueError(f"inverse models that bridge a delay of {delay} steps need forward models that see the "
                             f"{delay} previous commands")
        self.delay = int(delay)
        self.spec, self.forwards, self.inverses = spec, fwds, invs
        self.method, self.alpha, self.seed = method, float(alpha), seed
        self.member = 0
        self.rng = np.random.default_rng(seed)

    @property
    def commands(self) -> int:
        """c: the past commands (before the current one) the forward models see; callers pass them
        as ``past`` (0: none, the paper's one-step model; the delay d otherwise)."""
        return self.forwards[0].commands if self.forwards else 0

    def _check_actions(self, arr, lead: tuple, n: int, name: str, what: str, missing: str) -> np.ndarray | None:
        """``arr`` as float of shape (*lead, n*A) (n earlier actions, oldest first); None when n is 0.

        Raises:
            ValueError: ``arr`` missing (``missing`` says why it is needed) or of another shape.
        """
        if not n:
            return None
        if arr is None:
            raise ValueError(f"{missing}: give them as {name}")
        arr = np.asarray(arr, dtype=np.float64)
        want = (*lead, n * self.spec.action_dim)
        if arr.shape != want:
            raise ValueError(f"{name} must have shape {want} (the {n} {what}, oldest first), got {arr.shape}")
        return arr

    def _check_sent(self, sent, lead: tuple) -> np.ndarray | None:
        return self._check_actions(sent, lead, self.delay, "sent", "actions sent to the sim before",
                                   f"the inverse models bridge a delay of {self.delay} steps and need the "
                                   f"{self.delay} actions sent to the sim before this one")

    def _check_past(self, past, lead: tuple) -> np.ndarray | None:
        return self._check_actions(past, lead, self.commands, "past", "previous commands",
                                   f"the forward models see the {self.commands} previous commands")

    @property
    def forward(self):
        """The first member's forward model (None for the identity)."""
        return self.forwards[0] if self.forwards else None

    @property
    def inverse(self):
        """The first member's inverse model (None for the identity)."""
        return self.inverses[0] if self.inverses else None

    @property
    def n_members(self) -> int:
        return len(self.forwards)

    @property
    def is_identity(self) -> bool:
        return not self.forwards

    def reset(self, seed: int | None = None) -> None:
        """Re-seed the sampling generator (an episode's seed makes grounded rollouts repeatable) and,
        for an SGAT ensemble, draw the episode's member."""
        self.rng = np.random.default_rng(self.seed if seed is None else np.random.SeedSequence([int(seed), 0x5a7]))
        if self.n_members > 1 and self.method == "sgat":
            self.member = int(self.rng.integers(self.n_members))

    def _ground(self, k: int, hist: np.ndarray, a: np.ndarray, sample: bool, normal=None, past=None,
                sent=None) -> np.ndarray:
        """Member k's grounded action (before the blend); ``normal(shape)`` draws the SGAT noise
        (default: ``self.rng``); ``past``: the previous commands and ``sent``: the actions sent to the
        sim before (a delay)."""
        if self.delay and sent is None:
            raise ValueError(f"the inverse models bridge a delay of {self.delay} steps: give the actions sent before")
        fwd, inv = self.forwards[k], self.inverses[k]
        normal = normal or self.rng.standard_normal
        x = np.concatenate([hist, a] if past is None else [hist, past, a], axis=-1)
        if sample and fwd.stochastic:  # ForwardModel.sample with the given generator
            ds = fwd.sample_with(x, normal((*x.shape[:-1], fwd.noise_dim)))
        else:
            ds = fwd.predict(x)[0]
        # the target ŝ_{t+1} = s_t + Δŝ (ŝ_{t+d+1} with a delay), asked of the inverse model from the sim's state s_t
        return inv.predict(np.concatenate([hist] + ([sent] if self.delay else []) + [ds], axis=-1))

    def transform(self, hist: np.ndarray, a: np.ndarray, past: np.ndarray | None = None,
                  sent: np.ndarray | None = None) -> np.ndarray:
        """Grounded actions for state histories ``hist`` (..., k*S) and actions ``a`` (..., A);
        ``past`` (..., c*A): the c commands before ``a``, oldest first, and ``sent`` (..., d*A): the d
        actions sent to the sim before, oldest first (both required with a :attr:`delay` d; at an
        episode's first steps, pad with the first command).

        Raises:
            ValueError: ``past`` or ``sent`` missing or of the wrong shape.
        """
        a = np.asarray(a, dtype=np.float64)
        if self.is_identity:
            return a.copy()
        hist = np.asarray(hist, dtype=np.float64)
        past = self._check_past(past, a.shape[:-1])
        sent = self._check_sent(sent, a.shape[:-1])
        if self.samples:
            g = self._ground(self.member, hist, a, sample=True, past=past, sent=sent)
        else:
            g = self._mean_grounding(hist, a, past, sent)
        return self._blend(a, g)

    def _mean_grounding(self, hist, a, past, sent) -> np.ndarray:
        """The members' deterministic grounded actions averaged: GAT's (or SGAT's with deterministic
        models) answer."""
        return np.mean([self._ground(k, hist, a, sample=False, past=past, sent=sent) for k in range(self.n_members)], axis=0)

    def reach(self, hist: np.ndarray, step: np.ndarray, a: np.ndarray, sent: np.ndarray | None = None) -> np.ndarray:
        """The grounded action that asks for a given state change: the members' inverse models'
        answers to ``f_sim^-1(hist, step)`` averaged and blended with ``a`` at α (what
        :meth:`transform` does with a forward model's Δŝ; :class:`sgat.grounded.TeacherForcedEnv`
        gives the recorded one).

        Args:
            hist: state history (k*S,); step: the wanted change of the state from the sim's current
                one, s_target − s_t (S,; with a :attr:`delay` d, the target is d + 1 steps ahead);
                a: the agent's grounded actions (A,); sent: (d*A,) the d actions sent to the sim
                before (with a delay).

        Returns:
            (A,), clipped to the action bounds.

        Raises:
            ValueError: an identity transformer (no inverse models); ``sent`` missing or mis-shaped.
        """
        if self.is_identity:
            raise ValueError("an identity transformer has no inverse models to ask")
        a = np.asarray(a, dtype=np.float64)
        sent = self._check_sent(sent, a.shape[:-1])
        z = np.concatenate([hist] + ([sent] if self.delay else []) + [step])
        return self._blend(a, np.mean([inv.predict(z) for inv in self.inverses], axis=0))

    def _blend(self, a: np.ndarray, g: np.ndarray) -> np.ndarray:
        out = (1.0 - self.alpha) * a + self.alpha * g if self.alpha < 1.0 else g
        return np.clip(out, self.spec.action_low, self.spec.action_high)

    @property
    def samples(self) -> bool:
        """Whether :meth:`transform` draws noise: SGAT with stochastic forward models draws
        :attr:`noise_dim` standard normals from ``self.rng`` per call."""
        return bool(self.forwards) and self.method == "sgat" and self.forwards[0].stochastic

    @property
    def noise_dim(self) -> int:
        """Standard normals one SGAT step draws: ``spec.state_dim``, plus one that picks the component
        of a mixture-density forward model (:attr:`sgat.models.ForwardModel.noise_dim`)."""
        return self.forwards[0].noise_dim if self.forwards else self.spec.state_dim

    def transform_episodes(self, hist: np.ndarray, a: np.ndarray, members, noise: np.ndarray | None = None,
                           past: np.ndarray | None = None, sent: np.ndarray | None = None) -> np.ndarray:
        """:meth:`transform` for n episodes at once, each with its own ensemble member and noise.

        Args:
            hist: state histories (n, k*S); a: actions (n, A).
            members: n ensemble members (each episode's draw at :meth:`reset`).
            noise: (n, :attr:`noise_dim`) standard normal draws, row i the next draws of episode i's
                generator (needed when :attr:`samples`; a generator's draws of (T, d) at once are its
                next T draws of (d,), so a caller may draw a whole episode's noise at its start).
            past: (n, c*A) each episode's previous commands; sent: (n, d*A) the d actions sent to each
                episode's sim before (both needed with a :attr:`delay`).

        Returns:
            (n, A); row i is bit-identical to :meth:`transform` ``(hist[i], a[i])`` of a transformer
            with ``member = members[i]`` whose generator draws ``noise[i]`` (NumPy's matmul runs the
            same BLAS routine per item on (n, 1, d) stacks as on one (d,) row).

        Raises:
            ValueError: noise missing when the transformer samples; ``past`` or ``sent`` missing or
                mis-shaped.
        """
        a = np.asarray(a, dtype=np.float64)
        if self.is_identity:
            return a.copy()
        hist = np.asarray(hist, dtype=np.float64)
        h3, a3 = hist[:, None, :], a[:, None, :]
        p3 = self._check_past(past, a.shape[:-1])
        p3 = None if p3 is None else p3[:, None, :]
        e3 = self._check_sent(sent, a.shape[:-1])
        e3 = None if e3 is None else e3[:, None, :]
        if self.samples:
            if noise is None:
                raise ValueError("an SGAT transformer samples: give each episode's standard normal draws (noise)")
            noise = np.asarray(noise, dtype=np.float64)[:, None, :]
            members = np.asarray(members)
            g = np.empty_like(a3)
            for k in np.unique(members).tolist():
                sel = np.flatnonzero(members == k)
                g[sel] = self._ground(k, h3[sel], a3[sel], sample=True, normal=lambda shape, sel=sel: noise[sel],
                                      past=None if p3 is None else p3[sel], sent=None if e3 is None else e3[sel])
        else:
            g = self._mean_grounding(h3, a3, p3, e3)
        return self._blend(a3, g)[:, 0]

    # -- persistence ---------------------------------------------------------------------------
    @staticmethod
    def _files(n: int) -> list[tuple[str, str]]:
        if n == 1:
            return [("forward.pt", "inverse.pt")]
        return [(f"forward_{i}.pt", f"inverse_{i}.pt") for i in range(n)]

    def save(self, directory: str | os.PathLike) -> str:
        """Write the models (``forward.pt``/``inverse.pt``, or ``forward_<i>.pt``/``inverse_<i>.pt`` per
        ensemble member) and ``transformer.json`` (written last: its presence marks a complete save)."""
        directory = os.fspath(directory)
        os.makedirs(directory, exist_ok=True)
        for (ff, fi), f, i in zip(self._files(self.n_members), self.forwards, self.inverses):
            f.save(os.path.join(directory, ff))
            i.save(os.path.join(directory, fi))
        meta = {"method": self.method, "alpha": self.alpha, "seed": self.seed, "identity": self.is_identity,
                "members": self.n_members, "spec": self.spec.to_dict()}
        atomic_write_text(os.path.join(directory, "transformer.json"), json.dumps(meta, indent=1))
        return directory

    @classmethod
    def load(cls, directory: str | os.PathLike) -> "ActionTransformer":
        """Load what :meth:`save` wrote.

        Raises:
            FileNotFoundError: missing files. ModelFileError: corrupted or mismatched weights, or a
                transformer saved with settings this version does not have.
        """
        directory = os.fspath(directory)
        path = os.path.join(directory, "transformer.json")
        if not os.path.exists(path):
            raise FileNotFoundError(f"no transformer.json in {directory!r}")
        with open(path) as f:
            meta = json.load(f)
        gone = sorted(k for k in ("sim_forward", "matched", "noise_memory", "shadow_memory", "gate_scale") if meta.get(k))
        if gone:
            raise ModelFileError(f"{path!r} was saved with {', '.join(gone)}, which this version does not have")
        spec = GroundingSpec.from_dict(meta["spec"])
        fwds, invs = [], []
        if not meta["identity"]:
            S, A, k = spec.state_dim, spec.action_dim, spec.history
            for ff, fi in cls._files(int(meta.get("members", 1))):
                fwd = ForwardModel.load(os.path.join(directory, ff), expect_out=S)
                if fwd.n_in != k * S + (fwd.commands + 1) * A:
                    raise ModelFileError(f"{os.path.join(directory, ff)!r}: model has {fwd.n_in} inputs, "
                                         f"this setting needs {k * S + (fwd.commands + 1) * A}")
                fwds.append(fwd)
                inv = InverseModel.load(os.path.join(directory, fi), expect_out=A)
                want = (k + 1) * S + inv.commands * A
                if inv.n_in != want:
                    raise ModelFileError(f"{os.path.join(directory, fi)!r}: model has {inv.n_in} inputs, "
                                         f"this setting needs {want}")
                invs.append(inv)
        return cls(spec, fwds or None, invs or None, method=meta["method"], alpha=meta["alpha"], seed=meta["seed"])


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
            (SGAT paper §II.B: r_{t+1} = R(a_t, s_{t+1}), so the control cost uses a, not ã).
    """

    def __init__(self, env: gym.Env, transformer: ActionTransformer, *, ctrl_cost_weight: float | None = None):
        super().__init__(env)
        self.transformer = transformer
        self.ctrl_cost_weight = ctrl_cost_weight
        self._hist: deque = deque(maxlen=transformer.spec.history)
        self._past: deque = deque(maxlen=max(transformer.commands, 1))
        self._sent: deque = deque(maxlen=max(transformer.delay, 1))  # actions sent (a delay)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        self.start(seed, obs)
        return obs, info

    def start(self, seed: int | None, obs: np.ndarray) -> None:
        """Begin an episode with ``seed`` whose first observation is ``obs`` (what :meth:`reset` does
        after the env's reset; batched rollouts call it directly)."""
        self.transformer.reset(seed)
        s = self.transformer.spec.states(obs)
        self._hist.clear()
        self._hist.extend([s] * self.transformer.spec.history)
        self._past.clear()
        self._sent.clear()

    def ground(self, action) -> np.ndarray:
        """The action to apply for the agent's ``action`` (a new array), given the state history
        (and, for a transformer with a command history, the agent's earlier commands: each call
        appends ``action`` to them, so call it once per step).

        Raises:
            ValueError: wrong shape, NaN or infinite entries (non-identity transformer).
        """
        a = np.array(action, dtype=np.float64)  # a copy: the agent's array is never modified
        spec = self.transformer.spec
        applied = a.copy()
        if not self.transformer.is_identity:
            if a.shape != self.env.action_space.shape:
                raise ValueError(f"action must have shape {self.env.action_space.shape}, got {a.shape}")
            if not np.all(np.isfinite(a)):
                raise ValueError("action contains NaN or infinite values")
            hist = np.concatenate(list(self._hist))
            ag = a[spec.action_index]
            past = None
            if self.transformer.commands:
                if not self._past:  # the first step: pad with the first command (as stack_past does)
                    self._past.extend([ag] * self.transformer.commands)
                past = np.concatenate(list(self._past))
                self._past.append(ag)
            sent = self._sent_before(ag)
            applied[spec.action_index] = self.transformer.transform(hist, ag, past, sent)
            if sent is not None:
                self._sent.append(applied[spec.action_index].copy())
        return applied

    def _sent_before(self, ag: np.ndarray) -> np.ndarray | None:
        """The d actions sent before this step, oldest first (a transformer with a delay d; None
        without): at an episode's first step padded with the agent's first command, as the batched
        rollouts pad (the training rows pad with the first applied action, ``stack_past``)."""
        d = self.transformer.delay
        if not d:
            return None
        if not self._sent:
            self._sent.extend([ag] * d)
        return np.concatenate(list(self._sent))

    def observe(self, obs: np.ndarray) -> None:
        """Append the state of the new observation to the history."""
        self._hist.append(self.transformer.spec.states(obs))

    def step(self, action):
        a = np.array(action, dtype=np.float64)
        applied = self.ground(a)
        obs, reward, terminated, truncated, info = self.env.step(applied)
        info = dict(info)
        info.setdefault("applied_action", applied)
        info["commanded_action"] = a
        if self.ctrl_cost_weight is not None and "reward_ctrl" in info:
            agent_ctrl = -self.ctrl_cost_weight * float(np.sum(a ** 2))
            reward = reward - info["reward_ctrl"] + agent_ctrl
            info["reward_ctrl"] = agent_ctrl
        self.observe(obs)
        return obs, reward, terminated, truncated, info


class TeacherForcedEnv(GroundedEnv):
    """The grounded sim with the forward model replaced by a recorded real walk (teacher forcing).

    At step t the target is the real walk's next state s^real_{t+1} (s^real_{t+d+1} for a transformer
    with a delay d) instead of a forward model's prediction, and the inverse model is asked for it from the sim's own state:
    ``g = f_sim^-1(s_t, s^real_{t+1} − s_t)`` (the ensemble members' answers averaged), blended with
    the agent's action at the transformer's α. It is the grounded sim with a forward model that is
    exactly right for that walk, so it separates what the forward model gets wrong from what action
    grounding can do at all: if the sim falls where the real walk fell when it is pulled along the
    real joint trajectory, the action transformation can reproduce the fall and the forward model is
    what misses it. After the recording ends (the real robot fell, or the walk was over) the
    commands pass through ungrounded: the rest of the episode is the sim's own dynamics, so the
    outcome depends on the inverse models, α and the sim alone, not on the forward model.

    Args:
        env: the sim the transformer grounds.
        transformer: a fitted :class:`ActionTransformer` (its inverse models and α are used).
        reference: the real walk's grounding states, shape (T, S) (``transformer.spec.states`` of its
            observations; row t is s_t, observed before the t-th command).

    Raises:
        ValueError: an identity transformer, or a reference that is not (T >= 2, S) and finite.
    """

    def __init__(self, env: gym.Env, transformer: ActionTransformer, reference: np.ndarray):
        if transformer.is_identity:
            raise ValueError("teacher forcing needs a fitted transformer (its inverse models)")
        ref = np.asarray(reference, dtype=np.float64)
        S = transformer.spec.state_dim
        if ref.ndim != 2 or ref.shape[1] != S or len(ref) < 2 or not np.all(np.isfinite(ref)):
            raise ValueError(f"reference must be finite grounding states of shape (T >= 2, {S}), got {ref.shape}")
        super().__init__(env, transformer)
        self.reference = ref
        self._t = 0

    def start(self, seed: int | None, obs: np.ndarray) -> None:
        super().start(seed, obs)
        self._t = 0

    def ground(self, action) -> np.ndarray:
        t = self._t
        self._t += 1
        a = np.array(action, dtype=np.float64)
        if a.shape != self.env.action_space.shape or not np.all(np.isfinite(a)):
            raise ValueError(f"action must be finite with shape {self.env.action_space.shape}")
        d = self.transformer.delay
        if t + 1 + d >= len(self.reference):  # the recording is over: the sim's own dynamics
            return a
        spec = self.transformer.spec
        applied = a.copy()
        ag = a[spec.action_index]
        sent = self._sent_before(ag)
        applied[spec.action_index] = self.transformer.reach(np.concatenate(list(self._hist)), self.reference[t + 1 + d]
                                                            - self._hist[-1], ag, sent)
        if sent is not None:
            self._sent.append(applied[spec.action_index].copy())
        return applied
