"""The grounding step of Algorithm 1: transitions from rollouts -> fitted action transformer.

``f_real`` is fitted on real transitions ``(s_t, a_t, s_{t+1})`` (SGAT: Gaussian NLL; GAT: MSE)
and ``f_sim^-1`` on sim transitions collected with exploration noise on the actions, so that it
covers the next states the forward model proposes (Desai et al., IROS 2020, §III; the GAT code
adds noise to the sim policy for the same reason). The action of a transition is the one *applied*
to the world (for real data with a noisy actuator this is still the commanded one: the noise is
part of the real dynamics the forward model must learn).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from sgat.models import FitReport, ForwardModel, InverseModel
from sgat.transformer import METHODS, ActionTransformer, GroundingSpec


@dataclass
class Transitions:
    """Stacked transitions: histories H (N, k*S), applied actions A (N, A), state changes dS (N, S),
    commanded actions C (N, A) (None: the applied ones) and the c actions applied before each one,
    P (N, c*A), oldest first (None: c = 0; :func:`stack_past`)."""

    H: np.ndarray
    A: np.ndarray
    dS: np.ndarray
    C: np.ndarray | None = None
    P: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.H)

    @property
    def commands(self) -> np.ndarray:
        return self.A if self.C is None else self.C

    @classmethod
    def concat(cls, parts: list["Transitions"]) -> "Transitions":
        if not parts:
            raise ValueError("no transitions")
        C = None if all(p.C is None for p in parts) else np.concatenate([p.commands for p in parts])
        if len({p.past_commands for p in parts}) > 1:
            raise ValueError("transitions with different numbers of past actions cannot be stacked")
        P = None if parts[0].P is None else np.concatenate([p.P for p in parts])
        return cls(*(np.concatenate([getattr(p, f) for p in parts]) for f in ("H", "A", "dS")), C, P)

    @property
    def past_commands(self) -> int:
        """c: the number of earlier actions each row holds in ``P``."""
        return 0 if self.P is None else self.P.shape[1] // max(self.A.shape[1], 1)

    def forward_input(self) -> np.ndarray:
        """The forward model's input rows ``[H, P, A]`` (:class:`sgat.models.ForwardModel`), (N, k*S + (c+1)*A)."""
        return np.concatenate([self.H] + ([] if self.P is None else [self.P]) + [self.A], 1)


def stack_past(A: np.ndarray, c: int) -> np.ndarray:
    """(T, A) actions of one trajectory -> (T, c*A): row t holds ``a_{t-c}, ..., a_{t-1}``, oldest
    first, padded with ``a_0`` before the start (as the transformer pads at an episode's first step)."""
    A = np.asarray(A, dtype=np.float64)
    idx = np.clip(np.arange(len(A))[:, None] + np.arange(-c, 0)[None], 0, None)
    return A[idx].reshape(len(A), -1)


def trajectory_transitions(obs: np.ndarray, actions: np.ndarray, spec: GroundingSpec,
                           commands: np.ndarray | None = None, past: int = 0, delay: int = 0) -> Transitions:
    """Transitions of one trajectory: ``obs`` (T, n_obs) observed before each ``actions`` (T, n_act)
    was applied (row t of ``obs`` is s_t; the transition t -> t+1 uses actions[t]); ``commands``
    (T, n_act): what the agent commanded (None: the applied actions); ``past``: how many earlier
    applied actions each transition keeps (``P``, for a forward model with a command history);
    ``delay`` d: the transitions bridge d + 1 steps, ``dS`` = s_{t+d+1} − s_t (for models of a world
    whose actuators answer a command d control steps late, ``GroundingConfig.delay``; 0: one step).

    Raises:
        ValueError: mismatched lengths, fewer than d + 2 steps, past < 0 or delay < 0.
    """
    if int(past) < 0 or int(delay) < 0:
        raise ValueError(f"past and delay must be >= 0, got {past}, {delay}")
    d = int(delay)
    obs = np.asarray(obs, dtype=np.float64)
    actions = np.asarray(actions, dtype=np.float64)
    if len(obs) != len(actions) or len(obs) < d + 2 or (commands is not None and len(commands) != len(obs)):
        raise ValueError(f"need >= {d + 2} observation/action rows of equal length, got {len(obs)} and {len(actions)}")
    S = spec.states(obs)
    H = spec.stack_history(S)
    n = len(S) - 1 - d
    C = None if commands is None else np.asarray(commands, dtype=np.float64)[:n][:, spec.action_index]
    A = actions[:, spec.action_index]
    P = stack_past(A, int(past))[:n] if past else None
    return Transitions(H[:n], A[:n], S[1 + d:] - S[:n], C, P)


def recording_observations(rec, layout) -> np.ndarray:
    """The observation matrix (N, layout.size) of an ``envs.Recording`` (columns ``layout.names``).

    Raises:
        KeyError: a needed observation column is missing from the recording (all named).
    """
    missing = [n for n in layout.names if n not in rec.columns]
    if missing:
        raise KeyError(f"recording lacks observation column(s) {', '.join(missing)} needed for grounding")
    return np.stack([rec.columns[n] for n in layout.names], axis=1)


def recording_transitions(recs, layout, spec: GroundingSpec, past: int = 0, delay: int = 0) -> Transitions:
    """Transitions of ``envs.Recording``s: applied actions (``app``, else ``cmd``) and commands (``cmd``);
    ``past``: earlier applied actions kept per transition; ``delay``: steps bridged beyond one
    (:func:`trajectory_transitions`). Recordings shorter than ``delay + 2`` rows are skipped."""
    parts = [trajectory_transitions(recording_observations(r, layout), r.group("app"), spec, r.group("cmd"), past, delay)
             for r in recs if len(r) >= 2 + int(delay)]
    return Transitions.concat(parts)


def command_visibility(recs, layout, spec: GroundingSpec, leads=(1, 2, 3, 4, 5), folds: int = 2) -> dict:
    """How much of the exploration noise on a sim's commands its walks reveal k steps later: the
    identifiability of ``f_sim^-1`` at each lead k.

    The inverse model of a grounding step learns the *applied* action a_t from the state history
    and the state change (:class:`sgat.models.InverseModel`). Its training walks carry white
    exploration noise ε_t = a_t − c_t on the agent's commands c_t; the part of ε_t that a linear map
    of ``[s_{t-h+1}, ..., s_t, s_{t+k} − s_t]`` recovers is what the state change at lead k says
    about the action. In a sim whose actuators answer a command at once, k = 1 (the paper's
    one-step model) shows it; in a sim with an actuation latency of L control steps (the identified
    sim, whose diagnosis found one), s_{t+1}, ..., s_{t+L} do not depend on a_t at all, so a one-step
    inverse model can only return the commands it saw for similar states: the data gait's policy.

    Per lead k the ordinary least-squares fit (``numpy.linalg.lstsq``, with an intercept) is
    cross-validated over whole walks (walk i in fold ``i mod folds``): the returned R² is
    1 − Σ(ε − ε̂)² / Σ(ε − ε̄)² over the held-out rows of every fold and every grounded action
    entry, ε̄ the training rows' mean. R² ≈ 0: the state change at that lead carries nothing of
    the action (no better than its mean).

    Args:
        recs: ``envs.Recording`` walks of the sim with exploration noise (``app`` applied and
            ``cmd`` commanded actions), at least ``folds`` of them.
        layout: the ``envs.ObservationLayout`` of the recordings; ``spec``: the grounding spec (its
            state entries, history and grounded action entries are the inverse model's).
        leads: the leads k >= 1 to test [control steps].
        folds: walk folds of the cross-validation (>= 2).

    Returns:
        ``{"leads": [k...], "r2": [R² per lead], "best_lead": the k of the largest R², "rows":
        held-out rows at lead 1, "noise_rad": RMS exploration noise [rad]}``.

    Raises:
        ValueError: fewer walks than folds, folds < 2, a lead < 1, walks without exploration noise
            (applied equal to commanded), or no rows left at some lead (walks too short).
        KeyError: a recording lacks an observation column.
    """
    leads = [int(k) for k in leads]
    if folds < 2 or not leads or min(leads) < 1:
        raise ValueError(f"need folds >= 2 and leads >= 1, got folds={folds}, leads={leads}")
    walks = []
    for r in recs:
        S = spec.states(recording_observations(r, layout))
        eps = (r.group("app") - r.group("cmd"))[:, spec.action_index]
        walks.append((spec.stack_history(S), S, eps))
    if len(walks) < folds:
        raise ValueError(f"command_visibility needs at least {folds} walks, got {len(walks)}")
    noise = np.concatenate([w[2] for w in walks])
    if not np.any(noise):
        raise ValueError("the walks carry no exploration noise (applied actions equal the commands): nothing to recover")
    r2, rows = [], 0
    for k in leads:
        sse = sst = 0.0
        parts = []
        for H, S, eps in walks:
            n = len(S) - k
            parts.append(None if n < 1 else (np.hstack([H[:n], S[k:k + n] - S[:n], np.ones((n, 1))]), eps[:n]))
        for f in range(folds):
            train = [p for i, p in enumerate(parts) if i % folds != f and p is not None]
            test = [p for i, p in enumerate(parts) if i % folds == f and p is not None]
            if not train or not test:
                raise ValueError(f"no rows left at lead {k} in some fold: the walks are too short")
            X, y = np.vstack([p[0] for p in train]), np.vstack([p[1] for p in train])
            W = np.linalg.lstsq(X, y, rcond=None)[0]
            Xt, yt = np.vstack([p[0] for p in test]), np.vstack([p[1] for p in test])
            sse += float(((yt - Xt @ W) ** 2).sum())
            sst += float(((yt - y.mean(0)) ** 2).sum())
            if k == leads[0]:
                rows += len(Xt)
        r2.append(1.0 - sse / sst)
    return {"leads": leads, "r2": r2, "best_lead": leads[int(np.argmax(r2))], "rows": rows,
            "noise_rad": float(np.sqrt(np.mean(noise ** 2)))}


@dataclass(frozen=True)
class GroundingConfig:
    """How a grounding step fits its action transformer.

    Attributes:
        alpha: blend ã = (1 - α) a + α g(s, a) (required: 1 is the paper's formula, 0.5 the GAT code's).
        method: ``"sgat"`` (stochastic forward model, sampled) or ``"gat"`` (deterministic).
        hidden: hidden layer sizes of both models (the paper: (64, 64); (): linear models).
        ensemble: members (forward/inverse pairs) fitted on bootstrap resamples of the transitions with
            their own seeds; SGAT draws a member per episode (:class:`ActionTransformer`).
        components: SGAT's forward model as a mixture of this many diagonal Gaussians (a mixture
            density network, :class:`sgat.models.ForwardModel`; the SGAT paper's footnote); 1: one
            Gaussian, as the paper.
        delay: d, the actuation delay [control steps] of the sim being grounded that both models
            bridge (0: the paper's one-step models). A sim whose actuators answer a command d steps
            late (the identified sim with its identified latency) shows nothing of ``a_t`` in
            s_{t+1}, ..., s_{t+d} (:func:`command_visibility`), so a one-step inverse model returns
            the commands it saw for similar states, the data gait's, and its correction pulls every
            gait toward that one. With d > 0 the forward model predicts s_{t+d+1} − s_t from the state
            history, the d previous commands and ``a_t``; the inverse model answers that change given
            the d actions applied before ``a_t`` in the sim (:class:`sgat.models.InverseModel`
            ``commands``), which the transformer keeps per episode.
        max_epochs, lr, patience, batch_size: training of each model (Adam, mini-batches, early
            stopping after ``patience`` epochs without a better validation loss).

    Raises:
        ValueError: an unknown method, α outside [0, 1], ensemble or components < 1, delay < 0.
    """

    alpha: float
    method: str = "sgat"
    hidden: tuple = (64, 64)
    ensemble: int = 1
    components: int = 1
    delay: int = 0
    max_epochs: int = 150
    lr: float = 3e-3
    patience: int = 15
    batch_size: int = 128

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ValueError(f"unknown grounding method {self.method!r}; choose from {', '.join(METHODS)}")
        if not 0.0 <= float(self.alpha) <= 1.0:
            raise ValueError(f"alpha must be in [0, 1], got {self.alpha}")
        if int(self.ensemble) < 1:
            raise ValueError(f"ensemble must be >= 1, got {self.ensemble}")
        if int(self.components) < 1:
            raise ValueError(f"components must be >= 1, got {self.components}")
        if int(self.delay) < 0:
            raise ValueError(f"delay must be >= 0 control steps, got {self.delay}")
        object.__setattr__(self, "hidden", tuple(int(h) for h in self.hidden))

    def to_dict(self) -> dict:
        d = asdict(self)
        d["hidden"] = list(self.hidden)
        return d


@dataclass
class GroundingFit:
    """The fitted transformer and how the fits went (one report per ensemble member)."""

    transformer: ActionTransformer
    forward_reports: list[FitReport]
    inverse_reports: list[FitReport]
    info: dict = field(default_factory=dict)

    @property
    def forward_report(self) -> FitReport:
        return self.forward_reports[0]

    @property
    def inverse_report(self) -> FitReport:
        return self.inverse_reports[0]


def _fit_member(t: dict) -> dict:
    """Fit one ensemble member of :func:`fit_grounding` (a picklable task: its rows, seed and settings).

    Returns:
        ``{"forward", "forward_report", "inverse", "inverse_report"}``.
    """
    s, S, A, k, d, kw = t["seed"], t["S"], t["A"], t["history"], t["delay"], t["kw"]
    fwd = ForwardModel(S, A, history=k, stochastic=t["stochastic"], hidden=t["hidden"], components=t["components"],
                       commands=d)
    inv = InverseModel(S, A, history=k, hidden=t["hidden"], commands=d)
    return {"forward": fwd, "forward_report": fwd.fit(t["Xf"], t["Yf"], seed=s, **kw),
            "inverse": inv, "inverse_report": inv.fit(t["Xi"], t["Yi"], seed=s + 1, **kw)}


def fit_grounding(real: Transitions, sim: Transitions, spec: GroundingSpec, cfg: GroundingConfig, *,
                  seed: int = 0, map_fn=None) -> GroundingFit:
    """Fit ``f_real`` on ``real`` and ``f_sim^-1`` on ``sim`` (per ensemble member) and build the
    transformer (Algorithm 1, lines "update f_real, f_sim^-1").

    Member 0 is fitted on all transitions with ``seed``; further members on bootstrap resamples
    (rows drawn with replacement) with seeds ``seed + 7919 i`` (bagging: Breiman 1996; deep ensembles:
    Lakshminarayanan et al., NeurIPS 2017).

    With ``cfg.delay`` d > 0 both ``real`` and ``sim`` must bridge d + 1 steps and hold d past actions
    (``recording_transitions(..., past=d, delay=d)``). ``map_fn``: a ``map(fn, tasks) -> list`` that
    fits the ensemble's members side by side (e.g. an executor's ``map``: one member per worker). Each
    member is fitted from its own seed with the same operations wherever it runs, so the fit does not
    depend on it (given one torch thread per process, as the executors set).

    Raises:
        ValueError: unusable data (see :meth:`sgat.models._Model.fit`), or transitions without the
            past actions the delay asks for.
    """
    S, A, k = spec.state_dim, spec.action_dim, spec.history
    d = int(cfg.delay)
    if real.past_commands != d or (d and sim.past_commands != d):
        raise ValueError(f"the config's delay is {d} but the transitions hold {real.past_commands} past actions (real) "
                         f"and {sim.past_commands} (sim): build them with past={d}, delay={d}")
    kw = {"max_epochs": cfg.max_epochs, "lr": cfg.lr, "patience": cfg.patience, "batch_size": cfg.batch_size}
    Xf, Yf = real.forward_input(), real.dS
    Xi, Yi = np.concatenate([sim.H] + ([sim.P] if d else []) + [sim.dS], 1), sim.A
    sgat = cfg.method == "sgat"
    tasks = []
    for i in range(int(cfg.ensemble)):
        s = seed + 7919 * i
        fi = np.arange(len(Xf)) if i == 0 else np.random.default_rng([s, 1]).integers(0, len(Xf), len(Xf))
        ii = np.arange(len(Xi)) if i == 0 else np.random.default_rng([s, 2]).integers(0, len(Xi), len(Xi))
        tasks.append({"seed": s, "S": S, "A": A, "history": k, "stochastic": sgat, "hidden": cfg.hidden, "delay": d,
                      "components": int(cfg.components) if sgat else 1, "kw": kw, "Xf": Xf[fi], "Yf": Yf[fi],
                      "Xi": Xi[ii], "Yi": Yi[ii]})
    members = list((map_fn or map)(_fit_member, tasks))
    tr = ActionTransformer(spec, [m["forward"] for m in members], [m["inverse"] for m in members], method=cfg.method,
                           alpha=cfg.alpha, seed=seed)
    return GroundingFit(tr, [m["forward_report"] for m in members], [m["inverse_report"] for m in members],
                        {"n_real": len(real), "n_sim": len(sim)})


def fit_transformer(real: Transitions, sim: Transitions, spec: GroundingSpec, *, method: str = "sgat",
                    hidden=(64, 64), alpha: float, seed: int = 0, fit_kwargs: dict | None = None) -> GroundingFit:
    """One forward/inverse pair (no ensemble): :func:`fit_grounding` with keyword settings.

    Args:
        method: ``"sgat"`` (stochastic forward model, sampled) or ``"gat"`` (deterministic).
        alpha: the blend (required).
        fit_kwargs: ``lr``, ``max_epochs``, ``patience``, ``batch_size`` of the fits.

    Raises:
        ValueError: unknown method, unknown fit setting, or unusable data.
    """
    kw = dict(fit_kwargs or {})
    unknown = set(kw) - {"lr", "max_epochs", "patience", "batch_size"}
    if unknown:
        raise ValueError(f"unknown fit setting(s) {sorted(unknown)}; use lr, max_epochs, patience, batch_size")
    cfg = GroundingConfig(alpha=alpha, method=method, hidden=tuple(hidden), **kw)
    return fit_grounding(real, sim, spec, cfg, seed=seed)
