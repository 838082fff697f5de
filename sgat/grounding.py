"""The grounding step of Algorithm 1: transitions from rollouts -> fitted action transformer.

``f_real`` is fitted on real transitions ``(s_t, a_t, s_{t+1})`` (SGAT: Gaussian NLL; GAT: MSE)
and ``f_sim^-1`` on sim transitions collected with exploration noise on the actions, so that it
covers the next states the forward model proposes (Desai et al., IROS 2020, §III; the GAT code
adds noise to the sim policy for the same reason). The action of a transition is the one *applied*
to the world (for real data with a noisy actuator this is still the commanded one: the noise is
part of the real dynamics the forward model must learn); the commanded one rides along for an
inverse model that is conditioned on it (:class:`sgat.models.InverseModel` ``command_input``).
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


def dad_transitions(replays, real_recs, layout, spec: GroundingSpec, past: int = 0) -> Transitions:
    """Data-as-Demonstrator transitions (Venkatraman et al., AAAI 2015, Algorithm 1) of the forward model.

    ``replays[i]`` is the grounded sim driven by the commands of the real walk ``real_recs[i]`` from
    the same start (``envs.rollout.CommandLog``). Row t pairs the grounded sim's state history at t
    and the real walk's action at t (applied ``app``, else ``cmd``; as :func:`recording_transitions`)
    with the change that would bring the sim's state to the real walk's next state,
    s^real_{t+1} − s̃_t: where the grounded sim has drifted from the real walk, the target leads back
    to it. Each pair of recordings gives min(len) − 1 rows (whichever ended first, by a fall or its
    length, ends them); ``past``: earlier real actions per row (:func:`stack_past`).

    Returns:
        :class:`Transitions` H (N, k*S), A and C (N, A), dS (N, S), P (N, past*A) or None.

    Raises:
        ValueError: different numbers of replays and real walks, or no pair with 2 common rows.
        KeyError: a recording lacks an observation column.
    """
    if len(replays) != len(real_recs):
        raise ValueError(f"{len(replays)} replays for {len(real_recs)} real walks")
    parts = []
    for rep, real in zip(replays, real_recs):
        n = min(len(rep), len(real))
        if n < 2:
            continue
        S_sim = spec.states(recording_observations(rep, layout))[:n]
        S_real = spec.states(recording_observations(real, layout))[:n]
        A = np.asarray(real.group("app"), dtype=np.float64)[:n][:, spec.action_index]
        C = np.asarray(real.group("cmd"), dtype=np.float64)[:n][:, spec.action_index]
        P = stack_past(A, int(past))[:-1] if past else None
        parts.append(Transitions(spec.stack_history(S_sim)[:-1], A[:-1], S_real[1:] - S_sim[:-1], C[:-1], P))
    if not parts:
        raise ValueError("no replay and real walk share 2 steps: no DAD transitions")
    return Transitions.concat(parts)


@dataclass(frozen=True)
class GroundingConfig:
    """How a grounding step fits its action transformer.

    Attributes:
        alpha: blend ã = (1 - α) a + α g(s, a) (required: 1 is the paper's formula, 0.5 the GAT code's).
        method: ``"sgat"`` (stochastic forward model, sampled) or ``"gat"`` (deterministic).
        hidden: hidden layer sizes of both models (the paper: (64, 64)).
        ensemble: members (forward/inverse pairs) fitted on bootstrap resamples of the transitions with
            their own seeds; SGAT draws a member per episode (:class:`ActionTransformer`).
        inverse_command: the inverse model also sees the commanded action (a denoising inverse model,
            :class:`sgat.models.InverseModel`).
        components: SGAT's forward model as a mixture of this many diagonal Gaussians (a mixture
            density network, :class:`sgat.models.ForwardModel`; the SGAT paper's footnote); 1: one
            Gaussian, as the paper.
        noise_memory: correlation time [control steps] of SGAT's sampling noise (0: white, as the
            paper; :class:`sgat.transformer.ActionTransformer`).
        shadow_memory: τ [control steps] of the transformer's shadow state (0: the paper, every
            prediction starts from the sim's state; :class:`sgat.transformer.ActionTransformer`).
            A deployment setting: the fitted models are the same. Measured for the NAO (docs/grounding_history.md,
            ``sgatwalk fidelity``, ninth round): τ = 2 steps forecast gaits around θ0 better on the
            held-out panel (bias +2.5 -> -0.5, Brier 0.28 -> 0.20), but CMA-ES in that world found
            gaits that fall more often than the paper's transformer's (Table I), so 0 stays the default.
        command_history: c, the forward model also sees the c actions commanded before ``a_t``
            (:class:`sgat.models.ForwardModel` ``commands``). A one-step model f(s_t, a_t) cannot
            represent an actuation latency: the real joint answers a command given some steps ago,
            which neither s_t nor a_t shows; with the command history the transformer can (0: the
            paper's one-step model).
        residual_noise: SGAT on a stochastic sim: also fit a stochastic forward model of the sim and
            sample the real forward model with the variance the sim does not already have
            (:class:`sgat.transformer.ActionTransformer` ``sim_forward``).
        matched: a matched transformer: also fit a deterministic forward model of the sim on the sim
            transitions and ground with the difference of the inverse model's answers to the two
            forward models, g(s, a) = a + f_sim^-1(s, ŝ_real) − f_sim^-1(s, ŝ_sim)
            (:class:`sgat.transformer.ActionTransformer` ``sim_mean``). Where the real and the sim
            forward models agree, the grounded action is ``a`` itself, at any state; the inverse
            model's own error, which grows at states away from the data it was fitted on (other
            gaits), cancels (exactly, for linear models).
        local_inverse: a joint-local inverse model (linear models only): the command of joint j is
            regressed on joint j's own state entries only (its angle and velocity over the history and
            their change; :func:`local_inverse_mask`). A position-servoed joint's command is explained
            by its own response; an inverse model that sees every joint also learns the data gait's
            policy (the command from the whole body's phase) and pulls other gaits toward it.
        zero_init: linear models start from zero weights (:meth:`sgat.models._Model.fit`
            ``zero_init``), not PyTorch's random ones.
        dad_iterations: rounds of Data as Demonstrator (Venkatraman, Hebert and Bagnell, "Improving
            multi-step prediction of learned time series models", AAAI 2015, Algorithm 1) for the
            forward model: the grounded sim replays each real walk's commands, and the states it
            visits, labelled with the real walk's next states (:func:`dad_transitions`), join the
            forward model's training data; the forward models are refitted, the inverse models kept
            (:func:`experiments.runtime.grounding.fit_nao_grounding`). A one-step forward model is fitted on
            real states only, but in the grounded sim it predicts from the states the grounded sim
            reaches; DAD teaches it where the real robot went from those. 0: the paper.
        gate: the correction gated by the ensemble's disagreement (:class:`sgat.transformer.ActionTransformer`
            ``gate_scale``): its reference D_ref is this quantile, in (0, 1], of the disagreement over
            the real transitions the forward models were fitted on; at states where the members
            disagree more, the correction shrinks toward the agent's action in proportion. Needs an
            ensemble of at least 2. 0: no gate (the paper).
        delay: d, the actuation delay [control steps] of the sim being grounded that both models
            bridge (0: the paper's one-step models). A sim whose actuators answer a command d steps
            late (the identified sim with its identified latency) shows nothing of ``a_t`` in
            s_{t+1}, ..., s_{t+d} (:func:`command_visibility`), so a one-step inverse model returns
            the commands it saw for similar states, the data gait's, and its correction pulls every
            gait toward that one. With d > 0 the forward model predicts s_{t+d+1} − s_t from the state
            history, the d previous commands and ``a_t`` (``command_history`` d); the inverse model
            answers that change given the d actions applied before ``a_t`` in the sim
            (:class:`sgat.models.InverseModel` ``commands``), which the transformer keeps per episode.
            Works with the paper's transformer and an ensemble (no shadow state, matched or residual
            sim models, DAD, gate or joint-local inverse model); ``command_history`` must be 0 or d.
        max_epochs, lr, patience, batch_size: training of each model (Adam, mini-batches, early
            stopping after ``patience`` epochs without a better validation loss).
    """

    alpha: float
    method: str = "sgat"
    hidden: tuple = (64, 64)
    ensemble: int = 1
    inverse_command: bool = False
    residual_noise: bool = False
    components: int = 1
    noise_memory: float = 0.0
    shadow_memory: float = 0.0
    command_history: int = 0
    matched: bool = False
    zero_init: bool = False
    local_inverse: bool = False
    dad_iterations: int = 0
    gate: float = 0.0
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
        if not (np.isfinite(self.noise_memory) and self.noise_memory >= 0):
            raise ValueError(f"noise_memory must be a finite number of steps >= 0, got {self.noise_memory}")
        if not (np.isfinite(self.shadow_memory) and self.shadow_memory >= 0):
            raise ValueError(f"shadow_memory must be a finite number of steps >= 0, got {self.shadow_memory}")
        if self.shadow_memory > 0 and (self.matched or self.residual_noise):
            raise ValueError("shadow_memory works with the paper's transformer only (not matched or residual_noise)")
        if int(self.command_history) < 0:
            raise ValueError(f"command_history must be >= 0, got {self.command_history}")
        if int(self.dad_iterations) < 0:
            raise ValueError(f"dad_iterations must be >= 0, got {self.dad_iterations}")
        if not (np.isfinite(self.gate) and 0.0 <= self.gate <= 1.0):
            raise ValueError(f"gate must be a quantile in [0, 1] (0: no gate), got {self.gate}")
        if self.gate > 0 and int(self.ensemble) < 2:
            raise ValueError(f"gate needs an ensemble of at least 2 members, got ensemble={self.ensemble}")
        if self.gate > 0 and self.shadow_memory > 0:
            raise ValueError("gate works without a shadow state (shadow_memory 0)")
        if int(self.delay) < 0:
            raise ValueError(f"delay must be >= 0 control steps, got {self.delay}")
        if self.delay and (self.shadow_memory > 0 or self.matched or self.residual_noise or self.dad_iterations
                           or self.gate > 0 or self.local_inverse):
            raise ValueError("delay works with the paper's transformer only (no shadow_memory, matched, residual_noise, "
                             "dad_iterations, gate or local_inverse)")
        if self.delay and int(self.command_history) not in (0, int(self.delay)):
            raise ValueError(f"with delay {self.delay} the forward model sees the {self.delay} previous commands: "
                             f"command_history must be 0 or {self.delay}, got {self.command_history}")
        object.__setattr__(self, "hidden", tuple(int(h) for h in self.hidden))
        if self.local_inverse and self.hidden:
            raise ValueError(f"local_inverse needs linear models (hidden=()), got hidden={self.hidden}")

    @property
    def forward_commands(self) -> int:
        """c: the previous commands the forward model sees (``command_history``, or ``delay`` when set)."""
        return int(self.delay) or int(self.command_history)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["hidden"] = list(self.hidden)
        # settings added later are left out at their defaults, so saved configs and caches still match
        for k, default in (("components", 1), ("noise_memory", 0.0), ("shadow_memory", 0.0), ("command_history", 0),
                           ("matched", False), ("zero_init", False), ("local_inverse", False), ("dad_iterations", 0),
                           ("gate", 0.0), ("delay", 0)):
            if d[k] == default:
                d.pop(k)
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


def local_inverse_mask(spec: GroundingSpec, *, command_input: bool = False) -> np.ndarray:
    """Which inputs of the inverse model each grounded action may use in a joint-local inverse model.

    Input layout (:class:`sgat.models.InverseModel`): ``[s_{t-k+1}, ..., s_t, s_{t+1} - s_t]`` (+ ``a_t``).
    Action j (named after its joint, e.g. ``LKneePitch``) may use the state entries of the same joint
    (``q.LKneePitch``, ``dq.LKneePitch``) in every frame and in the change, and (``command_input``)
    its own command. A state joint that no action is named after is given to the action whose name
    matches it without its side letter, if exactly one does: the NAO's ``RHipYawPitch`` is driven by
    the ``LHipYawPitch`` command (one motor).

    Returns:
        A boolean array (A, (k + 1) S [+ A]).

    Raises:
        ValueError: the spec has no state or action names, or an action has no state entry of its joint.
    """
    if not spec.state_names or not spec.action_names:
        raise ValueError("a joint-local inverse model needs a grounding spec with state and action names")
    actions = list(spec.action_names)
    owner = []
    for n in spec.state_names:
        j = n.split(".", 1)[-1]  # q.LKneePitch -> LKneePitch
        if j in actions:
            owner.append(actions.index(j))
            continue
        side = [i for i, a in enumerate(actions) if j[:1] in "LR" and a[:1] in "LR" and a[1:] == j[1:]]
        owner.append(side[0] if len(side) == 1 else -1)
    owner = np.array(owner)
    per_frame = owner[None, :] == np.arange(len(actions))[:, None]  # (A, S)
    lonely = [a for i, a in enumerate(actions) if not per_frame[i].any()]
    if lonely:
        raise ValueError(f"a joint-local inverse model: no state entry of joint(s) {', '.join(lonely)}")
    mask = np.tile(per_frame, (1, spec.history + 1))
    if command_input:
        mask = np.concatenate([mask, np.eye(len(actions), dtype=bool)], axis=1)
    return mask


def _fit_member(t: dict) -> dict:
    """Fit one ensemble member of :func:`fit_grounding` (a picklable task: its rows, seed and settings).

    Returns:
        ``{"forward", "forward_report"}`` and, when the task holds inverse rows, ``"inverse"``,
        ``"inverse_report"`` and the sim models the settings ask for (``"sim_forward"``, ``"sim_mean"``).
    """
    s, S, A, k, c, kw = t["seed"], t["S"], t["A"], t["history"], t["commands"], t["kw"]
    fwd = ForwardModel(S, A, history=k, stochastic=t["stochastic"], hidden=t["hidden"], components=t["components"],
                       commands=c)
    out = {"forward": fwd, "forward_report": fwd.fit(t["Xf"], t["Yf"], seed=s, **kw)}
    if "Xi" not in t:
        return out
    inv = InverseModel(S, A, history=k, hidden=t["hidden"], command_input=t["inverse_command"], commands=t.get("delay", 0))
    out.update(inverse=inv, inverse_report=inv.fit(t["Xi"], t["Yi"], seed=s + 1, input_mask=t["mask"], **kw))
    if t.get("residual_noise"):
        fs = ForwardModel(S, A, history=k, stochastic=True, hidden=t["hidden"], commands=c)
        fs.fit(t["Xs"], t["dSs"], seed=s + 2, **kw)
        out["sim_forward"] = fs
    if t.get("matched"):  # the sim's own mean transition, fitted like f_real on the inverse model's rows
        fm = ForwardModel(S, A, history=k, stochastic=False, hidden=t["hidden"], commands=c)
        fm.fit(t["Xs"], t["dSs"], seed=s + 3, **kw)
        out["sim_mean"] = fm
    return out


def fit_grounding(real: Transitions, sim: Transitions, spec: GroundingSpec, cfg: GroundingConfig, *,
                  seed: int = 0, forward_extra: Transitions | None = None,
                  previous: GroundingFit | None = None, map_fn=None) -> GroundingFit:
    """Fit ``f_real`` on ``real`` and ``f_sim^-1`` on ``sim`` (per ensemble member) and build the
    transformer (Algorithm 1, lines "update f_real, f_sim^-1").

    Member 0 is fitted on all transitions with ``seed``; further members on bootstrap resamples
    (rows drawn with replacement) with seeds ``seed + 7919 i`` (bagging: Breiman 1996; deep ensembles:
    Lakshminarayanan et al., NeurIPS 2017).

    With ``cfg.command_history`` c > 0 both ``real`` and ``sim`` must hold c past actions per
    transition (``recording_transitions(..., past=c)``); with ``cfg.delay`` d > 0 both must bridge d + 1
    steps and hold d past actions (``recording_transitions(..., past=d, delay=d)``).

    ``forward_extra``: more training rows of the forward models (:func:`dad_transitions`), stacked
    under ``real`` before the bootstrap resampling. ``previous``: a fit of the same data whose
    inverse models (and sim models) are kept: only the forward models are fitted again.
    ``map_fn``: a ``map(fn, tasks) -> list`` that fits the ensemble's members side by side (e.g. an
    ``experiments.runtime.executors`` executor's ``map``: one member per worker). Each member is fitted from
    its own seed with the same operations wherever it runs, so the fit does not depend on it (given one
    torch thread per process, as the executors set).

    Raises:
        ValueError: unusable data (see :meth:`sgat.models._Model.fit`), or transitions without the
            past actions the config asks for.
    """
    S, A, k = spec.state_dim, spec.action_dim, spec.history
    c, d = cfg.forward_commands, int(cfg.delay)
    if real.past_commands != c or ((cfg.residual_noise or cfg.matched or d) and sim.past_commands != c):
        raise ValueError(f"the config's command_history (or delay) is {c} but the transitions hold {real.past_commands} "
                         f"past actions (real) and {sim.past_commands} (sim): build them with past={c}")
    kw = {"max_epochs": cfg.max_epochs, "lr": cfg.lr, "patience": cfg.patience, "batch_size": cfg.batch_size,
          "zero_init": cfg.zero_init}
    if forward_extra is not None and forward_extra.past_commands != c:
        raise ValueError(f"the forward_extra transitions hold {forward_extra.past_commands} past actions, the config {c}")
    fwd_rows = real if forward_extra is None else Transitions.concat([real, forward_extra])
    Xf, Yf = fwd_rows.forward_input(), fwd_rows.dS
    inv_in = [sim.H] + ([sim.P] if d else []) + [sim.dS] + ([sim.commands] if cfg.inverse_command else [])
    Xi, Yi = np.concatenate(inv_in, 1), sim.A
    Xs = sim.forward_input()  # the sim's own forward model: applied actions in, its spread out
    mask = local_inverse_mask(spec, command_input=cfg.inverse_command) if cfg.local_inverse else None
    sgat = cfg.method == "sgat"
    tasks = []
    for i in range(int(cfg.ensemble)):
        s = seed + 7919 * i
        fi = np.arange(len(Xf)) if i == 0 else np.random.default_rng([s, 1]).integers(0, len(Xf), len(Xf))
        ii = np.arange(len(Xi)) if i == 0 else np.random.default_rng([s, 2]).integers(0, len(Xi), len(Xi))
        t = {"seed": s, "S": S, "A": A, "history": k, "stochastic": sgat, "hidden": cfg.hidden, "commands": c,
             "components": int(cfg.components) if sgat else 1, "kw": kw, "Xf": Xf[fi], "Yf": Yf[fi]}
        if previous is None:  # else the inverse (and sim) models stay
            t.update(Xi=Xi[ii], Yi=Yi[ii], inverse_command=cfg.inverse_command, mask=mask, delay=d)
            if (cfg.residual_noise and sgat) or cfg.matched:
                t.update(Xs=Xs[ii], dSs=sim.dS[ii], residual_noise=bool(cfg.residual_noise and sgat),
                         matched=bool(cfg.matched))
        tasks.append(t)
    members = list((map_fn or map)(_fit_member, tasks))
    fwds = [m["forward"] for m in members]
    rf = [m["forward_report"] for m in members]
    invs = [m["inverse"] for m in members if "inverse" in m]
    ri = [m["inverse_report"] for m in members if "inverse" in m]
    sims = [m["sim_forward"] for m in members if "sim_forward" in m]
    means = [m["sim_mean"] for m in members if "sim_mean" in m]
    if previous is not None:
        if previous.transformer.n_members != len(fwds):
            raise ValueError(f"previous fit has {previous.transformer.n_members} members, the config {len(fwds)}")
        old = previous.transformer
        invs, sims, means, ri = old.inverses, old.sim_forwards, old.sim_means, previous.inverse_reports
    tr = ActionTransformer(spec, fwds, invs, method=cfg.method, alpha=cfg.alpha, seed=seed, sim_forward=sims or None,
                           noise_memory=cfg.noise_memory, sim_mean=means or None, shadow_memory=cfg.shadow_memory)
    info = {"n_real": len(real), "n_sim": len(sim)}
    if cfg.gate > 0:  # D_ref: the disagreement's quantile over the real transitions (forward_extra left out)
        tr.set_gate(float(np.quantile(tr.disagreement(real.H, real.A, real.P), cfg.gate)))
        info["gate_scale"] = tr.gate_scale
    if forward_extra is not None:
        info["n_forward_extra"] = len(forward_extra)
    return GroundingFit(tr, rf, ri, info)


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
