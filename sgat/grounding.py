"""The grounding step of Algorithm 1: transitions from rollouts -> fitted action transformer.

``f_real`` is fitted on real transitions ``(s_t, a_t, s_{t+1})`` (SGAT: Gaussian NLL; GAT: MSE)
and ``f_sim^-1`` on sim transitions collected with exploration noise on the actions, so that it
covers the next states the forward model proposes (``reference/grounding.md`` §11, "narrow
inverse-model data"). The action of a transition is the one *applied* to the world (for real
data with a noisy actuator this is still the commanded one: the noise is part of the real
dynamics the forward model must learn).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from sgat.models import FitReport, ForwardModel, InverseModel
from sgat.transformer import ActionTransformer, GroundingSpec


@dataclass
class Transitions:
    """Stacked transitions: histories H (N, k*S), actions A (N, A), state changes dS (N, S)."""

    H: np.ndarray
    A: np.ndarray
    dS: np.ndarray

    def __len__(self) -> int:
        return len(self.H)

    @classmethod
    def concat(cls, parts: list["Transitions"]) -> "Transitions":
        if not parts:
            raise ValueError("no transitions")
        return cls(*(np.concatenate([getattr(p, f) for p in parts]) for f in ("H", "A", "dS")))


def trajectory_transitions(obs: np.ndarray, actions: np.ndarray, spec: GroundingSpec) -> Transitions:
    """Transitions of one trajectory: ``obs`` (T, n_obs) observed before each ``actions`` (T, n_act)
    was applied (row t of ``obs`` is s_t; the transition t -> t+1 uses actions[t]).

    Raises:
        ValueError: mismatched lengths or fewer than 2 steps.
    """
    obs = np.asarray(obs, dtype=np.float64)
    actions = np.asarray(actions, dtype=np.float64)
    if len(obs) != len(actions) or len(obs) < 2:
        raise ValueError(f"need >= 2 observation/action rows of equal length, got {len(obs)} and {len(actions)}")
    S = spec.states(obs)
    H = spec.stack_history(S)
    return Transitions(H[:-1], actions[:-1][:, spec.action_index], S[1:] - S[:-1])


def recording_observations(rec, layout) -> np.ndarray:
    """The observation matrix (N, layout.size) of an ``envs.Recording`` (columns ``layout.names``).

    Raises:
        KeyError: a needed observation column is missing from the recording.
    """
    missing = [n for n in layout.names if n not in rec.columns]
    if missing:
        raise KeyError(f"recording lacks observation column(s) {', '.join(missing[:5])} needed for grounding")
    return np.stack([rec.columns[n] for n in layout.names], axis=1)


def recording_transitions(recs, layout, spec: GroundingSpec) -> Transitions:
    """Transitions of ``envs.Recording``s, using their applied actions (``app``, else ``cmd``)."""
    parts = [trajectory_transitions(recording_observations(r, layout), r.group("app"), spec) for r in recs if len(r) >= 2]
    return Transitions.concat(parts)


@dataclass
class GroundingFit:
    """The fitted transformer and how the fits went."""

    transformer: ActionTransformer
    forward_report: FitReport
    inverse_report: FitReport
    info: dict = field(default_factory=dict)


def fit_transformer(real: Transitions, sim: Transitions, spec: GroundingSpec, *, method: str = "sgat",
                    hidden=(64, 64), alpha: float = 1.0, seed: int = 0, fit_kwargs: dict | None = None) -> GroundingFit:
    """Fit ``f_real`` on ``real`` and ``f_sim^-1`` on ``sim`` and build the transformer.

    Args:
        method: ``"sgat"`` (stochastic forward model, sampled) or ``"gat"`` (deterministic).
        fit_kwargs: passed to :meth:`sgat.models._Model.fit` (lr, max_epochs, patience, ...).

    Raises:
        ValueError: unknown method, or unusable data (see ``fit``).
    """
    if method not in ("sgat", "gat"):
        raise ValueError(f"unknown grounding method {method!r}; choose 'sgat' or 'gat'")
    kw = dict(fit_kwargs or {})
    S, A, k = spec.state_dim, spec.action_dim, spec.history
    fwd = ForwardModel(S, A, history=k, stochastic=(method == "sgat"), hidden=hidden)
    rf = fwd.fit(np.concatenate([real.H, real.A], 1), real.dS, seed=seed, **kw)
    inv = InverseModel(S, A, history=k, hidden=hidden)
    ri = inv.fit(np.concatenate([sim.H, sim.dS], 1), sim.A, seed=seed + 1, **kw)
    tr = ActionTransformer(spec, fwd, inv, method=method, alpha=alpha, seed=seed)
    return GroundingFit(tr, rf, ri, {"n_real": len(real), "n_sim": len(sim)})
