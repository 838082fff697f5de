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
import math
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
    """``(state history, action) -> grounded action``, NumPy inference.

    Args:
        spec: the :class:`GroundingSpec`.
        forward, inverse: fitted models, or equal-length lists of them (an ensemble: member i is the
            pair ``(forward[i], inverse[i])``); both None means the identity (before the first fit).
        method: ``"sgat"`` (sample the forward model) or ``"gat"`` (its mean).
        alpha: blend ã = (1 - α) a + α g(s, a), in [0, 1]; required when models are given (the
            paper's formula is α = 1; the GAT/GARAT code uses 0.5).
        seed: seed of the sampling generator (re-seeded by :meth:`reset`).
        noise_memory: correlation time [steps] of SGAT's sampling noise (0: white, the paper). With
            τ > 0 the standard normals behind each Δŝ sample form a stationary AR(1) process,
            z_t = c z_{t-1} + sqrt(1 - c²) ε_t with c = exp(-1/τ): every step's sample has the
            forward model's distribution, but deviations persist over about τ steps, as a real
            trial's do (a stiffer joint, a bump under the foot, for a whole stride) instead of
            averaging out within a stride.

    An ensemble expresses model uncertainty the way PETS's trajectory sampling does (Chua et al.,
    NeurIPS 2018, §4.2 "TS∞"): SGAT draws one member per episode at :meth:`reset` and keeps it for
    the whole episode, so a grounded sim is one plausible fit of the real data, not one arbitrary
    fit; GAT (deterministic) averages the members' predictions.

    ``sim_forward`` (SGAT on a *stochastic* sim, e.g. the identified sim with random ground): a
    stochastic forward model of the sim itself per member. The paper's SGAT assumes a deterministic
    sim, so all of the real world's spread must come from the sampled Δŝ; a sim that already has
    random ground would then get its spread twice. With ``sim_forward`` the sample is drawn with the
    residual variance only, Δŝ ~ N(μ_real, max(σ²_real − σ²_sim, 0)), and the sim adds its own.

    ``shadow_memory`` (τ [steps]; 0: the paper): the forward model predicts from a **shadow state**
    ŝ_t, the transformer's own estimate of where the real robot would be, instead of from the sim's
    state s_t. The target is ŝ_{t+1} = ŝ_t + Δŝ, Δŝ ~ f_real(ŝ history, a_t), and the inverse model
    is asked for it from the sim's state, g = f_sim^-1(s_t, ŝ_{t+1} − s_t); after the step the
    shadow relaxes toward the sim's new state, ŝ_{t+1} ← s_{t+1} + e^{-1/τ} (ŝ_{t+1} − s_{t+1})
    (:meth:`relax_shadow`). With τ = 0 ŝ_t = s_t: every step's prediction starts again from wherever
    the sim got to, so a deviation from the target the sim did not follow is forgotten at once. With
    τ > 0 it persists for about τ steps and the transformer keeps pushing toward it, as it does when
    the targets are a real walk's recorded states (teacher forcing, :class:`TeacherForcedEnv`):
    the real joint trajectory drifts away from the sim's for whole strides (the ground under a
    foot), which one-step samples anchored at the sim's state never do.

    ``sim_mean`` (a *matched* transformer): a deterministic forward model of the sim per member.
    The grounded action is then g(s, a) = a + f_sim^-1(s, ŝ_real) − f_sim^-1(s, ŝ_sim) with ŝ_sim the
    sim model's prediction: the transformer corrects by the inverse model's answer to the gap
    between the two forward models, so it is the identity wherever they agree, and the inverse
    model's error at states unlike its training data (another gait's) cancels instead of becoming a
    systematic offset of the commands (exactly so for linear models: then g − a = B (Δŝ_real − Δŝ_sim)
    with B the inverse model's weights on Δs). It is the control-variate form of the paper's
    f_sim^-1(s, ŝ_real), which equals it when f_sim^-1(s, ŝ_sim) = a.

    ``gate_scale`` (D_ref [rad]; None: the paper): the correction is **gated by the ensemble's
    disagreement**. At each step the members' deterministic grounded actions g_k (each member's mean
    Δŝ through its own inverse model) disagree by D = RMS over members and joints of g_k − mean_k g_k
    (:meth:`disagreement`); the blend becomes ã = a + α w (g − a) with w = min(1, D_ref / D). Where
    the members agree as well as on the real transitions they were fitted on (D ≤ D_ref, a quantile
    of D over those transitions, ``GroundingConfig.gate``), the correction is the paper's; at states
    unlike that data (another gait's), where the bootstrap fits disagree, it shrinks toward the
    agent's action: the world falls back to the sim under it (for hybrid grounding, the identified
    sim) instead of extrapolating a correction learned on one gait. Epistemic uncertainty from a
    bootstrap ensemble as in PETS (Chua et al., NeurIPS 2018) and MOPO's disagreement penalty (Yu
    et al., NeurIPS 2020, §4.3), used here to shrink the action correction instead of the reward.
    Teacher forcing (:meth:`reach`) is not gated.

    **Delay** d (inverse models with ``commands`` d, ``GroundingConfig.delay``; 0: the paper): for a
    sim whose actuators answer a command d control steps late, a_t first shows in s_{t+d+1}. The forward
    models then predict Δŝ = ŝ_{t+d+1} − s_t from the state history, the agent's d previous commands
    (``past``) and a_t, and the inverse models answer it given the d actions the sim was sent before
    (``sent``: the transformer's own earlier outputs, which callers keep per episode):
    g = f_sim^-1(s_t, â_{t-d}, ..., â_{t-1}, ŝ_{t+d+1} − s_t). Works without shadow state and
    without matched or residual sim models and gate.

    Raises:
        ValueError: unknown method, α missing or outside [0, 1], only one kind of model given,
            ensembles of different sizes, models whose sizes do not match the spec, or a gate on an
            ensemble of fewer than 2 members, with a shadow state, or with a D_ref that is not finite
            and > 0; inverse models that disagree on their delay, a delay with forward models that do
            not see that many previous commands, or with a shadow state, sim models or a gate.
    """

    def __init__(self, spec: GroundingSpec, forward=None, inverse=None, *, method: str = "sgat",
                 alpha: float | None = None, seed: int = 0, sim_forward=None, noise_memory: float = 0.0,
                 sim_mean=None, shadow_memory: float = 0.0, gate_scale: float | None = None):
        if not (math.isfinite(float(noise_memory)) and float(noise_memory) >= 0.0):
            raise ValueError(f"noise_memory must be a finite number of steps >= 0, got {noise_memory}")
        if not (math.isfinite(float(shadow_memory)) and float(shadow_memory) >= 0.0):
            raise ValueError(f"shadow_memory must be a finite number of steps >= 0, got {shadow_memory}")
        if float(shadow_memory) > 0 and (_members(sim_forward) or _members(sim_mean)):
            raise ValueError("shadow_memory works with the paper's transformer only (no sim_forward or sim_mean models)")
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
        if len({i.command_input for i in invs}) > 1:
            raise ValueError("ensemble members disagree on whether the inverse model sees the command")
        sims = _members(sim_forward)
        if sims and (len(sims) != len(fwds) or not all(m.stochastic for m in sims)):
            raise ValueError("give one stochastic sim forward model per ensemble member, or none")
        means = _members(sim_mean)
        if means and (len(means) != len(fwds) or any(m.stochastic for m in means)):
            raise ValueError("give one deterministic sim forward model per ensemble member (sim_mean), or none")
        if len({f.commands for f in fwds + sims + means}) > 1:
            raise ValueError("forward models disagree on the number of past commands they see")
        if len({i.commands for i in invs}) > 1:
            raise ValueError("ensemble members disagree on the delay their inverse models bridge")
        delay = invs[0].commands if invs else 0
        if delay and (fwds[0].commands != delay or float(shadow_memory) > 0 or sims or means or gate_scale is not None):
            raise ValueError(f"inverse models that bridge a delay of {delay} steps need forward models that see the "
                             f"{delay} previous commands, and no shadow state, sim models or gate")
        self.delay = int(delay)
        self.spec, self.forwards, self.inverses, self.sim_forwards = spec, fwds, invs, sims
        self.sim_means = means
        self.method, self.alpha, self.seed = method, float(alpha), seed
        self.member = 0
        self.rng = np.random.default_rng(seed)
        self.noise_memory = float(noise_memory)
        self._c = math.exp(-1.0 / self.noise_memory) if self.noise_memory > 0 else 0.0
        self._s = math.sqrt(1.0 - self._c ** 2)
        self._z = None
        self.shadow_memory = float(shadow_memory)
        self._beta = math.exp(-1.0 / self.shadow_memory) if self.shadow_memory > 0 else 0.0
        #: Δŝ of the last :meth:`transform` call (the shadow's predicted change), shape (S,) or (..., S).
        self.last_delta = None
        self.gate_scale = None
        if gate_scale is not None:
            self.set_gate(gate_scale)

    def set_gate(self, gate_scale: float | None) -> None:
        """Gate the correction by the ensemble's disagreement with reference D_ref = ``gate_scale``
        [rad] (None: no gate; see the class docstring).

        Raises:
            ValueError: fewer than 2 members, a shadow state, or D_ref not finite and > 0.
        """
        if gate_scale is None:
            self.gate_scale = None
            return
        g = float(gate_scale)
        if not (math.isfinite(g) and g > 0):
            raise ValueError(f"gate_scale (D_ref) must be a finite number > 0, got {gate_scale}")
        if self.n_members < 2:
            raise ValueError("a disagreement gate needs an ensemble of at least 2 members")
        if self.shadow_memory > 0:
            raise ValueError("a disagreement gate works without a shadow state (shadow_memory 0)")
        if self.delay:
            raise ValueError("a disagreement gate works without a delay (inverse models of one step)")
        self.gate_scale = g

    @property
    def commands(self) -> int:
        """c: the past commands (before the current one) the forward models see; callers pass them
        as ``past`` (0: none, the paper's one-step model)."""
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
        self._z = None
        if self.n_members > 1 and self.method == "sgat":
            self.member = int(self.rng.integers(self.n_members))

    def _ground(self, k: int, hist: np.ndarray, a: np.ndarray, sample: bool, normal=None, past=None,
                shadow=None, sent=None) -> tuple[np.ndarray, np.ndarray]:
        """Member k's grounded action and the predicted state change Δŝ; ``normal(shape)`` draws the
        SGAT noise (default: ``self.rng``); ``past``: the previous commands (forward models with a
        command history); ``shadow``: the shadow state history the forward model predicts from
        (``shadow_memory`` > 0; None: the sim's, ``hist``); ``sent``: the actions sent to the sim
        before (a delay)."""
        if self.delay and sent is None:
            raise ValueError(f"the inverse models bridge a delay of {self.delay} steps: give the actions sent before")
        fwd, inv = self.forwards[k], self.inverses[k]
        S = self.spec.state_dim
        normal = normal or self.rng.standard_normal
        src = hist if shadow is None else shadow
        x = np.concatenate([src, a] if past is None else [src, past, a], axis=-1)
        if not sample:
            ds = fwd.predict(x)[0]
        elif self.sim_forwards:
            mu, sd = fwd.predict(x)  # a mixture: its mean and total spread
            sd_sim = self.sim_forwards[k].predict(x)[1]
            ds = mu + np.sqrt(np.maximum(sd ** 2 - sd_sim ** 2, 0.0)) * normal((*mu.shape[:-1], fwd.noise_dim))[..., -S:]
        elif fwd.stochastic:  # ForwardModel.sample with the given generator
            ds = fwd.sample_with(x, normal((*x.shape[:-1], fwd.noise_dim)))
        else:
            ds = fwd.predict(x)[0]
        # the target ŝ_{t+1} = ŝ_t + Δŝ (ŝ_{t+d+1} with a delay), asked of the inverse model from the sim's state s_t
        step = ds if shadow is None else ds + (shadow[..., -S:] - hist[..., -S:])
        z = [hist] + ([sent] if self.delay else []) + [step] + ([a] if inv.command_input else [])
        g = inv.predict(np.concatenate(z, axis=-1))
        if self.sim_means:  # matched: subtract the inverse model's answer to the sim's own prediction
            ds_sim = self.sim_means[k].predict(x)[0]
            z = [hist, ds_sim, a] if inv.command_input else [hist, ds_sim]
            g = a + g - inv.predict(np.concatenate(z, axis=-1))
        return g, ds

    def transform(self, hist: np.ndarray, a: np.ndarray, past: np.ndarray | None = None,
                  shadow: np.ndarray | None = None, sent: np.ndarray | None = None) -> np.ndarray:
        """Grounded actions for state histories ``hist`` (..., k*S) and actions ``a`` (..., A);
        ``past`` (..., c*A): the c commands before ``a``, oldest first (required when
        :attr:`commands` > 0; at an episode's first steps, pad with the first command); ``shadow``
        (..., k*S): the shadow state history (required when ``shadow_memory`` > 0; at an episode's
        start, the sim's); ``sent`` (..., d*A): the d actions sent to the sim before, oldest first
        (required with a :attr:`delay` d; at an episode's first steps, pad with the first command).
        The predicted change Δŝ is left in :attr:`last_delta`.

        Raises:
            ValueError: ``past``, ``shadow`` or ``sent`` missing or of the wrong shape.
        """
        a = np.asarray(a, dtype=np.float64)
        if self.is_identity:
            return a.copy()
        hist = np.asarray(hist, dtype=np.float64)
        past = self._check_past(past, a.shape[:-1])
        shadow = self._check_shadow(shadow, hist.shape)
        sent = self._check_sent(sent, a.shape[:-1])
        means = None
        if self.method == "sgat" and self.forwards[0].stochastic:
            g, ds = self._ground(self.member, hist, a, sample=True, normal=self._normal if self._c > 0 else None,
                                 past=past, shadow=shadow, sent=sent)
        else:
            means = self._member_outputs(hist, a, past, shadow, sent)
            g, ds = np.mean([g for g, _ in means], axis=0), np.mean([d for _, d in means], axis=0)
        self.last_delta = ds
        return self._blend(a, g, self._gate(hist, a, past, means))

    def _member_outputs(self, hist, a, past, shadow=None, sent=None) -> list[tuple[np.ndarray, np.ndarray]]:
        """Every member's deterministic (grounded action, Δŝ): averaged, GAT's (or SGAT's with
        deterministic models) answer; their spread, the gate's disagreement."""
        return [self._ground(k, hist, a, sample=False, past=past, shadow=shadow, sent=sent) for k in range(self.n_members)]

    @staticmethod
    def _spread(outs) -> np.ndarray:
        G = np.stack([g for g, _ in outs])
        return np.sqrt(np.mean((G - G.mean(axis=0)) ** 2, axis=(0, -1)))

    def disagreement(self, hist: np.ndarray, a: np.ndarray, past: np.ndarray | None = None) -> np.ndarray:
        """The ensemble's disagreement D [rad] on its grounded actions: the RMS over members and
        grounded joints of g_k − mean_k g_k, with g_k member k's deterministic grounded action (its
        forward model's mean Δŝ through its inverse model, before the blend).

        Args:
            hist: state histories (..., k*S); a: actions (..., A); past: (..., c*A) the previous
                commands (forward models with a command history).

        Returns:
            (...,) ≥ 0; zeros for fewer than 2 members.

        Raises:
            ValueError: ``past`` missing or mis-shaped.
        """
        a = np.asarray(a, dtype=np.float64)
        if self.n_members < 2:
            return np.zeros(a.shape[:-1])
        hist = np.asarray(hist, dtype=np.float64)
        past = self._check_past(past, a.shape[:-1])
        return self._spread(self._member_outputs(hist, a, past))

    def _gate(self, hist, a, past, outs=None) -> np.ndarray | None:
        """The gate's weights w = min(1, D_ref / D), shape (..., 1); None without a gate."""
        if self.gate_scale is None:
            return None
        D = self._spread(outs if outs is not None else self._member_outputs(hist, a, past))
        return np.minimum(1.0, self.gate_scale / np.maximum(D, 1e-300))[..., None]

    def _check_shadow(self, shadow, shape: tuple) -> np.ndarray | None:
        if not self.shadow_memory:
            return None
        if shadow is None:
            raise ValueError("the transformer keeps a shadow state (shadow_memory > 0): give its history as shadow")
        shadow = np.asarray(shadow, dtype=np.float64)
        if shadow.shape != shape:
            raise ValueError(f"shadow must have the shape of the state history {shape}, got {shadow.shape}")
        return shadow

    def relax_shadow(self, target: np.ndarray, state: np.ndarray) -> np.ndarray:
        """The shadow state after a step: the target ŝ_{t+1} = ŝ_t + Δŝ relaxed toward the sim's new
        state s_{t+1}, s_{t+1} + e^{-1/τ} (ŝ_{t+1} − s_{t+1}) (arrays (..., S); τ = ``shadow_memory``)."""
        state = np.asarray(state, dtype=np.float64)
        return state + self._beta * (np.asarray(target, dtype=np.float64) - state)

    def reach(self, hist: np.ndarray, step: np.ndarray, a: np.ndarray, sent: np.ndarray | None = None) -> np.ndarray:
        """The grounded action that asks for a given state change: the members' inverse models'
        answers to ``f_sim^-1(hist, step)`` averaged and blended with ``a`` at α (what
        :meth:`transform` does with a forward model's Δŝ; :class:`TeacherForcedEnv` gives the
        recorded one).

        Args:
            hist: state history (k*S,); step: the wanted change of the state from the sim's
                current one, s_target − s_t (S,; with a :attr:`delay` d, the target is d + 1 steps
                ahead); a: the agent's grounded actions (A,); sent: (d*A,) the d actions sent to
                the sim before (with a delay).

        Returns:
            (A,), clipped to the action bounds.

        Raises:
            ValueError: an identity transformer (no inverse models); ``sent`` missing or mis-shaped.
        """
        if self.is_identity:
            raise ValueError("an identity transformer has no inverse models to ask")
        a = np.asarray(a, dtype=np.float64)
        sent = self._check_sent(sent, a.shape[:-1])
        pre = [hist] + ([sent] if self.delay else []) + [step]
        g = np.mean([inv.predict(np.concatenate(pre + [a] if inv.command_input else pre)) for inv in self.inverses],
                    axis=0)
        return self._blend(a, g)

    def _blend(self, a: np.ndarray, g: np.ndarray, w: np.ndarray | None = None) -> np.ndarray:
        if w is not None:  # the gate: ã = a + α w (g − a)
            out = a + (self.alpha * w) * (g - a)
        else:
            out = (1.0 - self.alpha) * a + self.alpha * g if self.alpha < 1.0 else g
        return np.clip(out, self.spec.action_low, self.spec.action_high)

    @property
    def samples(self) -> bool:
        """Whether :meth:`transform` draws noise: SGAT with stochastic forward models draws
        :attr:`noise_dim` standard normals from ``self.rng`` per call."""
        return bool(self.forwards) and self.method == "sgat" and self.forwards[0].stochastic

    def _normal(self, shape) -> np.ndarray:
        """The next step's SGAT noise with memory: z_t = c z_{t-1} + sqrt(1 - c²) ε_t, z_0 = ε_0."""
        eps = self.rng.standard_normal(shape)
        self._z = eps if self._z is None else self._c * self._z + self._s * eps
        return self._z

    def correlate(self, Z: np.ndarray) -> np.ndarray:
        """An episode's standard normal draws (T, d), drawn at once, turned in place into the noise
        :meth:`transform` uses step by step (the same arithmetic: bit-identical); white noise
        (``noise_memory`` 0) is returned as it is."""
        if self._c > 0:
            for t in range(1, len(Z)):
                Z[t] = self._c * Z[t - 1] + self._s * Z[t]
        return Z

    @property
    def noise_dim(self) -> int:
        """Standard normals one SGAT step draws: ``spec.state_dim``, plus one that picks the component
        of a mixture-density forward model (:attr:`sgat.models.ForwardModel.noise_dim`)."""
        return self.forwards[0].noise_dim if self.forwards else self.spec.state_dim

    def transform_episodes(self, hist: np.ndarray, a: np.ndarray, members, noise: np.ndarray | None = None,
                           past: np.ndarray | None = None, shadow: np.ndarray | None = None,
                           delta_out: np.ndarray | None = None, sent: np.ndarray | None = None) -> np.ndarray:
        """:meth:`transform` for n episodes at once, each with its own ensemble member and noise.

        Args:
            hist: state histories (n, k*S); a: actions (n, A).
            members: n ensemble members (each episode's draw at :meth:`reset`).
            noise: (n, :attr:`noise_dim`) standard normal draws, row i the next draws of episode i's
                generator (needed when :attr:`samples`; a generator's draws of (T, d) at once are its
                next T draws of (d,), so a caller may draw a whole episode's noise at its start).
            past: (n, c*A) each episode's previous commands (needed when :attr:`commands` > 0).
            shadow: (n, k*S) each episode's shadow state history (needed when ``shadow_memory`` > 0).
            delta_out: (n, S), filled with each episode's predicted change Δŝ if given.
            sent: (n, d*A) the d actions sent to each episode's sim before (needed with a :attr:`delay`).

        With a gate (``gate_scale``) each row's weight comes from the whole ensemble's deterministic
        outputs at that row, as in :meth:`transform`.

        Returns:
            (n, A); row i is bit-identical to :meth:`transform` ``(hist[i], a[i])`` of a transformer
            with ``member = members[i]`` whose generator draws ``noise[i]`` (NumPy's matmul runs the
            same BLAS routine per item on (n, 1, d) stacks as on one (d,) row).

        Raises:
            ValueError: noise missing when the transformer samples; ``past`` missing or mis-shaped.
        """
        a = np.asarray(a, dtype=np.float64)
        if self.is_identity:
            return a.copy()
        hist = np.asarray(hist, dtype=np.float64)
        h3, a3 = hist[:, None, :], a[:, None, :]
        p3 = self._check_past(past, a.shape[:-1])
        p3 = None if p3 is None else p3[:, None, :]
        s3 = self._check_shadow(shadow, hist.shape)
        s3 = None if s3 is None else s3[:, None, :]
        e3 = self._check_sent(sent, a.shape[:-1])
        e3 = None if e3 is None else e3[:, None, :]
        means = None  # the members' deterministic outputs, when they are computed anyway (GAT)
        if self.samples:
            if noise is None:
                raise ValueError("an SGAT transformer samples: give each episode's standard normal draws (noise)")
            noise = np.asarray(noise, dtype=np.float64)[:, None, :]
            members = np.asarray(members)
            g = np.empty_like(a3)
            ds = np.empty((len(a3), 1, self.spec.state_dim))
            for k in np.unique(members).tolist():
                sel = np.flatnonzero(members == k)
                g[sel], ds[sel] = self._ground(k, h3[sel], a3[sel], sample=True, normal=lambda shape, sel=sel: noise[sel],
                                               past=None if p3 is None else p3[sel], shadow=None if s3 is None else s3[sel],
                                               sent=None if e3 is None else e3[sel])
        else:
            means = self._member_outputs(h3, a3, p3, s3, e3)
            g, ds = np.mean([g for g, _ in means], axis=0), np.mean([d for _, d in means], axis=0)
        if delta_out is not None:
            delta_out[...] = ds[:, 0]
        return self._blend(a3, g, self._gate(h3, a3, p3, means))[:, 0]

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
        for (ff, _), m in zip(self._files(self.n_members), self.sim_forwards):
            m.save(os.path.join(directory, "sim_" + ff))
        for (ff, _), m in zip(self._files(self.n_members), self.sim_means):
            m.save(os.path.join(directory, "simmean_" + ff))
        meta = {"method": self.method, "alpha": self.alpha, "seed": self.seed, "identity": self.is_identity,
                "members": self.n_members, "sim_forward": bool(self.sim_forwards), "spec": self.spec.to_dict()}
        if self.sim_means:
            meta["matched"] = True
        if self.noise_memory > 0:
            meta["noise_memory"] = self.noise_memory
        if self.shadow_memory > 0:
            meta["shadow_memory"] = self.shadow_memory
        if self.gate_scale is not None:
            meta["gate_scale"] = self.gate_scale
        atomic_write_text(os.path.join(directory, "transformer.json"), json.dumps(meta, indent=1))
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
        fwds, invs, sims, means = [], [], [], []
        if not meta["identity"]:
            S, A, k = spec.state_dim, spec.action_dim, spec.history
            for ff, fi in cls._files(int(meta.get("members", 1))):
                for name, into in [(ff, fwds)] + ([("sim_" + ff, sims)] if meta.get("sim_forward") else []) \
                        + ([("simmean_" + ff, means)] if meta.get("matched") else []):
                    fwd = ForwardModel.load(os.path.join(directory, name), expect_out=S)
                    if fwd.n_in != k * S + (fwd.commands + 1) * A:
                        raise ModelFileError(f"{os.path.join(directory, name)!r}: model has {fwd.n_in} inputs, "
                                             f"this setting needs {k * S + (fwd.commands + 1) * A}")
                    into.append(fwd)
                inv = InverseModel.load(os.path.join(directory, fi), expect_out=A)
                want = (k + 1) * S + (inv.commands + int(inv.command_input)) * A
                if inv.n_in != want:
                    raise ModelFileError(f"{os.path.join(directory, fi)!r}: model has {inv.n_in} inputs, "
                                         f"this setting needs {want}")
                invs.append(inv)
        return cls(spec, fwds or None, invs or None, method=meta["method"], alpha=meta["alpha"], seed=meta["seed"],
                   sim_forward=sims or None, noise_memory=float(meta.get("noise_memory", 0.0)),
                   sim_mean=means or None, shadow_memory=float(meta.get("shadow_memory", 0.0)),
                   gate_scale=meta.get("gate_scale"))


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
        self._shadow: deque = deque(maxlen=transformer.spec.history)  # shadow states (shadow_memory > 0)
        self._target = None

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
        self._shadow.clear()
        self._shadow.extend([s] * self.transformer.spec.history)
        self._target = None

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
            shadow = np.concatenate(list(self._shadow)) if self.transformer.shadow_memory else None
            sent = self._sent_before(ag)
            applied[spec.action_index] = self.transformer.transform(hist, ag, past, shadow, sent)
            if sent is not None:
                self._sent.append(applied[spec.action_index].copy())
            if shadow is not None:
                self._target = self._shadow[-1] + self.transformer.last_delta
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
        """Append the state of the new observation to the history (and the relaxed target to the
        shadow history, :meth:`ActionTransformer.relax_shadow`)."""
        s = self.transformer.spec.states(obs)
        self._hist.append(s)
        if self._target is not None:
            self._shadow.append(self.transformer.relax_shadow(self._target, s))
            self._target = None

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
