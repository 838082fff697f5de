"""GAT and SGAT on finite MDPs: the toy examples and Cliff Walking of the SGAT paper.

Source: Desai, Karnan, Hanna, Warnell, Stone, "Stochastic Grounded Action Transformation for
Robot Learning in Simulation", IROS 2020 (arXiv:2008.01281): §II.D "Transferring to
a Stochastic Real World" (toy MDPs, Figs. 3–4), §III "SGAT" (Fig. 5, Algorithm 1) and §IV.A
"Cliff Walking" (Figs. 6–7). Figure numbers are those of the compiled paper, where the NAO
photo (``fig:lumpy_field_setup``) is Fig. 1 and the GAT diagram Fig. 2; the LaTeX labels are
``fig:toy1`` (3), ``fig:toy2`` (4), ``fig:toy3`` (5), ``fig:gridworld_diagram`` (6) and
``fig:grid_plot`` (7). Policy iteration and policy evaluation follow Sutton & Barto,
*Reinforcement Learning: An Introduction*, 2nd ed., §4.1–4.3 (undiscounted episodic tasks);
the guard against improper policies follows the stochastic-shortest-path analysis of
Bertsekas & Tsitsiklis, "An analysis of stochastic shortest path problems", Math. Oper. Res.
16(3), 1991.

It is the same algorithm as the continuous one, with every model exact or counted:

* an MDP is a transition tensor ``P[s, a, s']`` (probabilities), a reward tensor
  ``R[s, a, s']`` (the reward received on the transition ``s --a--> s'``; the paper writes
  ``r_{t+1} = R(a_t, s_{t+1})``, which is the special case that ignores ``s``), a boolean
  vector of terminal states (absorbing, zero reward; an episode ends on entering one) and a
  start state;
* ``f_real(s, a)``: the empirical next-state distribution of real transitions ``(s, a, s')``
  (:class:`ForwardModel`). SGAT samples from it; GAT takes its most likely next state
  (paper §II.C, §III);
* ``f⁻¹_sim(s, ŝ')``: the sim action that produces ``ŝ'`` from ``s`` in the deterministic
  simulator, read off ``P_sim`` (:func:`sim_inverse_table`);
* the action transformer ``g(s, a) = f⁻¹_sim(s, f_real(s, a))`` as a distribution over sim
  actions ``G[s, a, â]`` (:func:`action_transformer`) and the grounded MDP
  ``P_g[s, a, :] = Σ_â G[s, a, â] P_sim[s, â, :]`` with the sim's reward for the agent's own
  action, ``R_g[s, a, s'] = R_sim[s, a, s']`` (paper: "the reward from the grounded
  simulator", ``R(a_t, s_{t+1})``) (:func:`grounded_mdp`);
* the policy-improvement step is exact policy iteration on the grounded MDP
  (:func:`policy_iteration`), and Algorithm 1 alternates both steps (:func:`ground`).

Decisions where the paper is silent (each one is a parameter or documented where it is made):

* Cliff Walking's random direction is uniform over all four directions and *may* coincide with
  the chosen one, so that at noise 1 "every transition is random" and the policy has no effect
  (the paper's reason why GAT and SGAT tie at noise 1). The chosen move therefore happens
  with probability ``1 - 3p/4``.
* The −0.1 step reward is paid on every step, including the one that enters the goal or the
  cliff: the shortest path (13 steps) returns ``100 - 1.3 = 98.7``.
* Real data are collected with the current policy made ε-greedy (``explore``, default 0.1);
  a deterministic policy alone never shows ``f_real`` the other actions (in Fig. 3 the sim's
  favourite ``a1`` would then never be compared with a real ``a2``). Data accumulate over
  grounding steps, as in the GAT baseline of the GARAT code (Desai et al., NeurIPS 2020;
  ``rl_gat/gat.py``).
* ``(s, a)`` pairs with fewer than ``min_count`` real samples are not grounded: the
  transformer is the identity there (the sim's own transition), as before the first fit.
* Ties in ``f⁻¹_sim`` (several sim actions reach ``ŝ'``, e.g. two moves into walls) keep the
  agent's own action if it is one of them, else the lowest action index; an ``ŝ'`` that no sim
  action reaches from ``s`` maps to the agent's own action (no information to ground on).
* GAT's ``argmax`` ties prefer the sim's own outcome ``sim(s, a)``, else the lowest index.
* Undiscounted evaluation of an improper policy (one that, from some state, never terminates
  with positive probability) is guarded: those states get ``improper_value`` (default −1e6,
  standing in for the −∞ such a state is worth when every step costs reward).
* Real data per grounding step: ``real_episodes`` = 10,000 episodes (the paper gives no
  number; with ε = 0.1 this is ≈ 0.1–0.3 M transitions per step on Cliff Walking). Fewer
  leave rarely visited pairs poorly estimated, and SGAT's policy then trails the real
  optimum by up to about one evaluation standard error.
* Grounding stops when ``patience`` (default 2) consecutive grounding steps leave the policy
  unchanged, or after ``max_grounding_steps`` (default 30). At noise 1 every action is equally
  good and sampling noise keeps re-ordering them, so that case runs to the cap (harmlessly).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from sgat.algorithm import grounding_loop, new_progress

__all__ = [
    "TabularMDP",
    "ForwardModel",
    "count_transitions",
    "PolicyIterationResult",
    "RolloutResult",
    "EvalResult",
    "GroundingResult",
    "toy_deterministic",
    "toy_stochastic",
    "cliff_walking",
    "CLIFF_ACTIONS",
    "policy_evaluation",
    "q_values",
    "proper_policy",
    "policy_iteration",
    "sim_inverse_table",
    "action_transformer",
    "grounded_mdp",
    "rollout",
    "evaluate_policy",
    "ground",
]

Method = Literal["gat", "sgat"]

#: Cliff Walking action order: index -> name, and the (row, column) displacement of each move.
CLIFF_ACTIONS: tuple[str, ...] = ("up", "down", "left", "right")
_CLIFF_MOVES = np.array([(-1, 0), (1, 0), (0, -1), (0, 1)], dtype=int)

#: Default value of states from which a policy may never terminate (stands in for −∞).
IMPROPER_VALUE = -1e6


# --------------------------------------------------------------------------------------------
# MDPs
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class TabularMDP:
    """A finite, undiscounted, episodic MDP (Sutton & Barto §3.1–3.4).

    Attributes:
        P: ``(S, A, S)`` float, ``P[s, a, s']`` = probability of ``s'`` after action ``a`` in
            ``s``; rows sum to 1. Terminal states are absorbing: ``P[t, a, t] = 1``.
        R: ``(S, A, S)`` float, reward received on the transition ``s --a--> s'`` (the paper's
            ``R(a_t, s_{t+1})`` is the case that does not depend on ``s``); zero from terminal
            states.
        terminal: ``(S,)`` bool; an episode ends when it enters a terminal state.
        start: index of the start state (non-terminal).
        state_names, action_names: optional labels (for printing and tests).
        name: a label.

    Raises:
        ValueError: on inconsistent shapes, rows that are not distributions, a terminal start,
            or terminal states that are not absorbing with zero reward.
    """

    P: np.ndarray
    R: np.ndarray
    terminal: np.ndarray
    start: int
    state_names: tuple[str, ...] | None = None
    action_names: tuple[str, ...] | None = None
    name: str = ""

    def __post_init__(self) -> None:
        P = np.asarray(self.P, dtype=float)
        R = np.asarray(self.R, dtype=float)
        term = np.asarray(self.terminal, dtype=bool)
        if P.ndim != 3 or P.shape[0] != P.shape[2]:
            raise ValueError(f"P must have shape (S, A, S), got {P.shape}")
        if R.shape != P.shape:
            raise ValueError(f"R must have the shape of P {P.shape}, got {R.shape}")
        if term.shape != (P.shape[0],):
            raise ValueError(f"terminal must have shape ({P.shape[0]},), got {term.shape}")
        if np.any(P < 0) or not np.allclose(P.sum(-1), 1.0, atol=1e-9):
            raise ValueError("every row P[s, a, :] must be a probability distribution")
        if not np.all(np.isfinite(R)):
            raise ValueError("R must be finite")
        start = int(self.start)
        if not 0 <= start < P.shape[0] or term[start]:
            raise ValueError(f"start must be a non-terminal state index, got {self.start}")
        t = np.flatnonzero(term)
        if t.size and (not np.allclose(P[t, :, t], 1.0) or np.any(R[t] != 0)):
            raise ValueError("terminal states must be absorbing with zero reward")
        if self.state_names is not None and len(self.state_names) != P.shape[0]:
            raise ValueError("state_names must name every state")
        if self.action_names is not None and len(self.action_names) != P.shape[1]:
            raise ValueError("action_names must name every action")
        for k, v in (("P", P), ("R", R), ("terminal", term)):
            v.setflags(write=False)
            object.__setattr__(self, k, v)
        object.__setattr__(self, "start", start)

    @property
    def n_states(self) -> int:
        return self.P.shape[0]

    @property
    def n_actions(self) -> int:
        return self.P.shape[1]

    def is_deterministic(self) -> bool:
        """True if every ``P[s, a, :]`` is one-hot (the paper's simulators are)."""
        return bool(np.all(np.isclose(self.P.max(-1), 1.0)))

    def next_state(self) -> np.ndarray:
        """``(S, A)`` int: the next state of a deterministic MDP.

        Raises:
            ValueError: if the MDP is not deterministic.
        """
        if not self.is_deterministic():
            raise ValueError(f"MDP {self.name!r} is not deterministic")
        return self.P.argmax(-1)


def _toy(n_out: int, real_rows: list[dict[int, float]], rewards: list[float], name: str):
    """States s0 (start), s1..s_n (terminal, entering s_i pays rewards[i-1])."""
    S, A = n_out + 1, n_out
    R = np.zeros((S, A, S))
    R[0, :, 1:] = np.asarray(rewards, dtype=float)[None, :]
    term = np.arange(S) > 0

    def build(rows: list[dict[int, float]]) -> np.ndarray:
        P = np.zeros((S, A, S))
        for t in range(1, S):
            P[t, :, t] = 1.0
        for a, row in enumerate(rows):
            for s2, p in row.items():
                P[0, a, s2] = p
        return P

    names = tuple(f"s{i}" for i in range(S))
    acts = tuple(f"a{i + 1}" for i in range(A))
    sim = TabularMDP(build([{a + 1: 1.0} for a in range(A)]), R, term, 0, names, acts,
                     f"{name} simulator")
    real = TabularMDP(build(real_rows), R, term, 0, names, acts, f"{name} real world")
    return sim, real


def toy_deterministic() -> tuple[TabularMDP, TabularMDP]:
    """The deterministic toy example of the paper's Fig. 3 (``fig:toy1``, §II.D): ``(sim, real)``.

    From ``s0`` (start), action ``a1`` reaches ``s1`` (reward +1) and ``a2`` reaches ``s2``
    (reward −1) in the simulator (Fig. 3a); reality swaps them (Fig. 3b). States
    ``s0, s1, s2`` (indices 0–2), actions ``a1, a2`` (indices 0–1); ``s1, s2`` are terminal.
    The real optimum is ``a2``; grounded GAT and SGAT both choose ``a2`` (Fig. 3c).
    """
    return _toy(2, [{2: 1.0}, {1: 1.0}], [1.0, -1.0], "toy (Fig. 3)")


def toy_stochastic() -> tuple[TabularMDP, TabularMDP]:
    """The stochastic toy example of the paper's Figs. 4 and 5 (``fig:toy2``, ``fig:toy3``):
    ``(sim, real)``.

    Rewards for entering ``s1, s2, s3`` are +1, −1, +10 (terminal). Simulator (Fig. 4a):
    ``a_i -> s_i``. Real world (Fig. 4b): ``a1 -> s1``; ``a2 -> s2`` w.p. 0.8, ``s3`` w.p. 0.2;
    ``a3 -> s2``. Real values: ``a1`` 1, ``a2`` 1.2, ``a3`` −1, so ``a2`` is optimal; the sim
    optimum is ``a3``; the GAT grounded sim (Fig. 4c) prefers ``a1``, the SGAT grounded sim
    (Fig. 5) ``a2``. Indices: states ``s0..s3`` = 0..3, actions ``a1..a3`` = 0..2.
    """
    return _toy(3, [{1: 1.0}, {2: 0.8, 3: 0.2}, {2: 1.0}], [1.0, -1.0, 10.0], "toy (Figs. 4-5)")


def cliff_walking(
    noise: float = 0.0,
    *,
    rows: int = 4,
    cols: int = 12,
    goal_reward: float = 100.0,
    cliff_reward: float = -10.0,
    step_reward: float = -0.1,
) -> TabularMDP:
    """The Cliff Walking grid world of the paper's §IV.A (Fig. 6), with "real" noise ``p``.

    Layout: ``rows × cols`` cells (default 4 × 12, the classic Sutton & Barto Example 6.6
    layout; the paper does not state the size), state index ``s = row * cols + col`` with row 0
    at the top. Start = bottom-left, goal = bottom-right, cliff = the bottom row between them.
    Actions (:data:`CLIFF_ACTIONS`): 0 up, 1 down, 2 left, 3 right; a move into a wall leaves
    the agent where it is. Every step pays ``step_reward`` (−0.1), entering the goal adds
    ``goal_reward`` (+100), entering the cliff adds ``cliff_reward`` (−10); goal and cliff
    cells are terminal. Undiscounted.

    Noise: with probability ``noise`` the agent moves in a direction drawn uniformly from all
    four (it may coincide with the chosen one) instead of the chosen direction. ``noise = 0`` is
    the deterministic simulator, ``noise = 1`` makes every transition random and independent
    of the action (paper: "At a value of one, every transition is random").

    Args:
        noise: probability ``p`` in [0, 1] of a random move per step.

    Returns:
        a :class:`TabularMDP` with ``S = rows * cols``, ``A = 4``.

    Raises:
        ValueError: if ``noise`` is not in [0, 1] or the grid is smaller than 2 × 3.
    """
    noise = float(noise)
    if not 0.0 <= noise <= 1.0 or not np.isfinite(noise):
        raise ValueError(f"noise must be a probability in [0, 1], got {noise}")
    if rows < 2 or cols < 3:
        raise ValueError(f"the grid needs at least 2 rows and 3 columns, got {rows} x {cols}")
    S, A = rows * cols, len(CLIFF_ACTIONS)
    start, goal = (rows - 1) * cols, rows * cols - 1
    cliff = np.arange(start + 1, goal)
    term = np.zeros(S, dtype=bool)
    term[cliff] = True
    term[goal] = True

    r, c = np.divmod(np.arange(S), cols)
    nr = np.clip(r[:, None] + _CLIFF_MOVES[None, :, 0], 0, rows - 1)
    nc = np.clip(c[:, None] + _CLIFF_MOVES[None, :, 1], 0, cols - 1)
    dest = nr * cols + nc  # (S, 4): where each direction leads (walls: stay)

    P = np.zeros((S, A, S))
    s_idx = np.arange(S)
    for a in range(A):
        P[s_idx, a, dest[:, a]] += 1.0 - noise
        for d in range(A):
            P[s_idx, a, dest[:, d]] += noise / A
    P[term] = 0.0
    for t in np.flatnonzero(term):  # goal and cliff are absorbing
        P[t, :, t] = 1.0

    reward_in = np.full(S, step_reward)
    reward_in[goal] += goal_reward
    reward_in[cliff] += cliff_reward
    R = np.broadcast_to(reward_in[None, None, :], (S, A, S)).copy()
    R[term] = 0.0

    names = tuple(f"({i // cols},{i % cols})" for i in range(S))
    return TabularMDP(P, R, term, start, names, CLIFF_ACTIONS,
                      f"cliff walking {rows}x{cols}, noise {noise:g}")


# --------------------------------------------------------------------------------------------
# Policy evaluation and policy iteration (Sutton & Barto §4.1-4.3), undiscounted
# --------------------------------------------------------------------------------------------


def _as_policy(mdp: TabularMDP, policy: np.ndarray) -> np.ndarray:
    pi = np.asarray(policy)
    if pi.shape != (mdp.n_states,) or not np.issubdtype(pi.dtype, np.integer):
        raise ValueError(f"policy must be an int array of shape ({mdp.n_states},), "
                         f"got {pi.dtype} {pi.shape}")
    if np.any((pi < 0) | (pi >= mdp.n_actions)):
        raise ValueError(f"policy actions must lie in [0, {mdp.n_actions})")
    return pi.astype(np.intp)


def _improper_states(support: np.ndarray, terminal: np.ndarray) -> np.ndarray:
    """States from which a chain with transition support ``support (S, S)`` terminates w.p. < 1.

    A finite absorbing chain terminates with probability 1 from ``s`` iff every state
    reachable from ``s`` can still reach a terminal state.
    """
    can_end = terminal.copy()
    while True:
        new = can_end | (support & can_end[None, :]).any(1)
        if np.array_equal(new, can_end):
            break
        can_end = new
    bad = ~can_end
    while True:
        new = bad | (support & bad[None, :]).any(1)
        if np.array_equal(new, bad):
            break
        bad = new
    return bad & ~terminal


def policy_evaluation(
    mdp: TabularMDP, policy: np.ndarray, *, improper_value: float = IMPROPER_VALUE
) -> np.ndarray:
    """Exact undiscounted value ``v_π`` of a deterministic policy (Sutton & Barto eq. 4.4).

    Solves ``v = r_π + P_π v`` on the non-terminal states that terminate with probability 1
    (a nonsingular linear system); terminal states are worth 0. States from which ``π`` may
    never terminate (improper; their true value is −∞ when every step costs reward, as in
    Cliff Walking) get ``improper_value`` instead — the guard for the undiscounted case.

    Args:
        mdp: the MDP.
        policy: ``(S,)`` int, the action taken in each state.
        improper_value: value assigned to improper states (reward units).

    Returns:
        ``(S,)`` float, expected return from each state (reward units).

    Raises:
        ValueError: if ``policy`` has the wrong shape, dtype or action range.
    """
    pi = _as_policy(mdp, policy)
    S = mdp.n_states
    idx = np.arange(S)
    P_pi = mdp.P[idx, pi]  # (S, S)
    r_pi = (P_pi * mdp.R[idx, pi]).sum(-1)
    bad = _improper_states(P_pi > 0, mdp.terminal)
    v = np.zeros(S)
    v[bad] = improper_value
    ok = ~mdp.terminal & ~bad
    if ok.any():
        n = np.flatnonzero(ok)
        A = np.eye(n.size) - P_pi[np.ix_(n, n)]
        b = r_pi[n] + P_pi[np.ix_(n, np.flatnonzero(bad))] @ v[bad]
        v[n] = np.linalg.solve(A, b)
    return v


def q_values(mdp: TabularMDP, v: np.ndarray) -> np.ndarray:
    """Action values ``q(s, a) = Σ_s' P[s, a, s'] (R[s, a, s'] + v(s'))`` (S&B eq. 4.6).

    Args:
        v: ``(S,)`` state values. Returns ``(S, A)``; rows of terminal states are 0.
    """
    q = np.einsum("ijk,ijk->ij", mdp.P, mdp.R + np.asarray(v, dtype=float)[None, None, :])
    q[mdp.terminal] = 0.0
    return q


def proper_policy(mdp: TabularMDP) -> np.ndarray:
    """A policy that terminates with probability 1 from every state from which some policy can.

    Each state takes an action with a positive chance of moving one step closer (in the
    transition graph) to a terminal state, so from every such state termination within ``S``
    steps has positive probability, hence probability 1 overall. Used to start policy
    iteration with a proper policy, as stochastic-shortest-path theory requires.

    Returns:
        ``(S,)`` int; action 0 where no policy can reach a terminal state.
    """
    S = mdp.n_states
    support = mdp.P > 0  # (S, A, S)
    dist = np.where(mdp.terminal, 0, np.iinfo(np.int64).max // 2)
    for _ in range(S):
        via = np.where(support, dist[None, None, :], np.iinfo(np.int64).max // 2).min(-1)
        new = np.minimum(dist, via.min(-1) + 1)
        new[mdp.terminal] = 0
        if np.array_equal(new, dist):
            break
        dist = new
    via = np.where(support, dist[None, None, :], np.iinfo(np.int64).max // 2).min(-1)
    return via.argmin(-1).astype(np.intp)


@dataclass(frozen=True, eq=False)
class PolicyIterationResult:
    """Result of :func:`policy_iteration`: ``policy (S,)`` int, ``v (S,)``, ``q (S, A)``,
    number of improvement ``iterations`` and whether the policy became stable."""

    policy: np.ndarray
    v: np.ndarray
    q: np.ndarray
    iterations: int
    converged: bool


def policy_iteration(
    mdp: TabularMDP,
    policy0: np.ndarray | None = None,
    *,
    max_iter: int = 1000,
    tol: float = 1e-9,
    improper_value: float = IMPROPER_VALUE,
) -> PolicyIterationResult:
    """Policy iteration (Sutton & Barto §4.3) for an undiscounted episodic MDP.

    Alternates exact :func:`policy_evaluation` and greedy improvement until the policy is
    stable. Improvement keeps the current action unless another one is better by more than
    ``tol`` (S&B's fix for policies that switch between equally good actions forever).
    Guard for the undiscounted case: the start policy is made proper where possible (states on
    which ``policy0`` is improper take :func:`proper_policy`'s action) and improper states are
    valued ``improper_value`` during evaluation.

    Args:
        mdp: the MDP.
        policy0: ``(S,)`` int start policy; default :func:`proper_policy`.
        max_iter: cap on improvement steps.
        tol: improvement threshold in reward units.

    Returns:
        :class:`PolicyIterationResult`; ``converged`` is False if ``max_iter`` was reached.

    Raises:
        ValueError: for a malformed ``policy0``.
    """
    base = proper_policy(mdp)
    if policy0 is None:
        pi = base.copy()
    else:
        pi = _as_policy(mdp, policy0).copy()
        idx = np.arange(mdp.n_states)
        bad = _improper_states(mdp.P[idx, pi] > 0, mdp.terminal)
        pi[bad] = base[bad]
    v = policy_evaluation(mdp, pi, improper_value=improper_value)
    q = q_values(mdp, v)
    for it in range(1, max_iter + 1):
        best = q.argmax(-1)
        cur = q[np.arange(mdp.n_states), pi]
        change = (q.max(-1) > cur + tol) & ~mdp.terminal
        if not change.any():
            return PolicyIterationResult(pi, v, q, it - 1, True)
        pi = np.where(change, best, pi).astype(np.intp)
        v = policy_evaluation(mdp, pi, improper_value=improper_value)
        q = q_values(mdp, v)
    return PolicyIterationResult(pi, v, q, max_iter, False)


# --------------------------------------------------------------------------------------------
# Grounding: forward model of real, inverse model of sim, action transformer, grounded MDP
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class ForwardModel:
    """Tabular forward model of the real environment, ``f_real(s, a)`` (paper §II.C, §III).

    Attributes:
        probs: ``(S, A, S)`` empirical next-state distribution; rows with no data are 0.
        n: ``(S, A)`` number of real samples behind each row (``inf`` for an exact model).
    """

    probs: np.ndarray
    n: np.ndarray

    @classmethod
    def from_counts(cls, counts: np.ndarray) -> "ForwardModel":
        """From transition counts ``(S, A, S)`` (non-negative). Raises ValueError otherwise."""
        counts = np.asarray(counts, dtype=float)
        if counts.ndim != 3 or counts.shape[0] != counts.shape[2] or np.any(counts < 0):
            raise ValueError(
                f"counts must be non-negative with shape (S, A, S), got {counts.shape}")
        n = counts.sum(-1)
        probs = np.divide(counts, n[..., None], out=np.zeros_like(counts), where=n[..., None] > 0)
        return cls(probs, n)

    @classmethod
    def from_transitions(cls, n_states: int, n_actions: int, s: np.ndarray, a: np.ndarray,
                         s2: np.ndarray) -> "ForwardModel":
        """From real transitions ``(s_t, a_t, s_{t+1})``, three ``(N,)`` int arrays."""
        return cls.from_counts(count_transitions(n_states, n_actions, s, a, s2))

    @classmethod
    def exact(cls, real: TabularMDP) -> "ForwardModel":
        """The infinite-data limit: ``probs = P_real``, ``n = inf`` everywhere."""
        return cls(real.P.copy(), np.full(real.P.shape[:2], np.inf))


def count_transitions(n_states: int, n_actions: int, s, a, s2) -> np.ndarray:
    """``(S, A, S)`` int64 histogram of transitions ``(s, a, s2)`` (three ``(N,)`` int arrays)."""
    counts = np.zeros((n_states, n_actions, n_states), dtype=np.int64)
    np.add.at(counts, (np.asarray(s), np.asarray(a), np.asarray(s2)), 1)
    return counts


def sim_inverse_table(sim: TabularMDP) -> np.ndarray:
    """Inverse dynamics of a deterministic simulator, ``f⁻¹_sim(s, ŝ')`` (paper §II.C).

    ``inv[s, ŝ', a]`` is the sim action that takes ``s`` to ``ŝ'``, given that the agent chose
    ``a``: the agent's own ``a`` if it reaches ``ŝ'`` (ties, e.g. two moves into walls, keep
    the agent's action), else the lowest-index action that does; if no action reaches ``ŝ'``
    from ``s``, the agent's own ``a`` (nothing to ground on; the transition is left to the sim).

    Returns:
        ``(S, S, A)`` int.

    Raises:
        ValueError: if the simulator is not deterministic (the paper only treats
            deterministic simulators; a stochastic one would need a distributional inverse).
    """
    nxt = sim.next_state()  # (S, A)
    S, A = nxt.shape
    reach = nxt[:, None, :] == np.arange(S)[None, :, None]  # (S, S', A): a reaches s'
    own = np.broadcast_to(np.arange(A)[None, None, :], (S, S, A))
    first = np.where(reach.any(-1), reach.argmax(-1), -1)  # (S, S')
    inv = np.where(reach, own, np.where(first[..., None] >= 0, first[..., None], own))
    return inv.astype(np.intp)


def action_transformer(
    sim: TabularMDP, model: ForwardModel, method: Method, *, min_count: float = 1
) -> np.ndarray:
    """The action transformer ``g(s, a) = f⁻¹_sim(s, ŝ')`` as a distribution over sim actions.

    SGAT (paper §III, Fig. 5): ``ŝ' ~ f_real(s, a)``, so
    ``G[s, a, â] = Σ_{ŝ'} f_real(ŝ'|s, a) [f⁻¹_sim(s, ŝ') = â]``.
    GAT (paper §II.C, Figs. 3c/4c): ``ŝ' = argmax f_real(·|s, a)``, a one-hot ``G``; ties prefer
    the sim's own outcome ``sim(s, a)``, else the lowest state index.
    Pairs with fewer than ``min_count`` real samples, and terminal states, keep the agent's
    action (identity transformer, the state before the first fit).

    Args:
        sim: the deterministic simulator.
        model: the real forward model (same ``S, A``).
        method: ``"gat"`` or ``"sgat"``.
        min_count: samples needed before a pair is grounded (> 0).

    Returns:
        ``(S, A, A)`` float, rows sum to 1.

    Raises:
        ValueError: unknown method, shape mismatch, ``min_count <= 0`` or a stochastic sim.
    """
    if method not in ("gat", "sgat"):
        raise ValueError(f"method must be 'gat' or 'sgat', got {method!r}")
    if model.probs.shape != sim.P.shape:
        raise ValueError(f"forward model shape {model.probs.shape} != sim shape {sim.P.shape}")
    if not min_count > 0:
        raise ValueError(f"min_count must be positive, got {min_count}")
    inv = sim_inverse_table(sim)  # (S, S', A)
    S, A = sim.n_states, sim.n_actions
    s_i, a_i = np.meshgrid(np.arange(S), np.arange(A), indexing="ij")  # (S, A)
    if method == "sgat":
        f = model.probs
    else:
        nxt = sim.next_state()
        score = model.probs.copy()
        m = score.max(-1, keepdims=True)
        is_max = np.isclose(score, m, rtol=0, atol=1e-12) & (m > 0)
        own = is_max[s_i, a_i, nxt]  # the sim's own outcome is among the maxima
        choice = np.where(own, nxt, is_max.argmax(-1))
        f = np.zeros_like(score)
        f[s_i, a_i, choice] = 1.0
    a_hat = inv[s_i[..., None], np.arange(S)[None, None, :], a_i[..., None]]  # (S, A, S')
    G = np.zeros((S, A, A))
    np.add.at(G, (s_i[..., None].repeat(S, -1), a_i[..., None].repeat(S, -1), a_hat), f)
    keep = (model.n < min_count) | sim.terminal[:, None]
    G[keep] = 0.0
    G[s_i[keep], a_i[keep], a_i[keep]] = 1.0
    return G


def grounded_mdp(sim: TabularMDP, G: np.ndarray, *, name: str = "") -> TabularMDP:
    """The grounded simulator (paper Figs. 3c, 4c, 5): the sim with ``a`` replaced by ``â ~ G``.

    ``P_g[s, a, :] = Σ_â G[s, a, â] P_sim[s, â, :]``; the reward is the sim's reward for the
    agent's own action, ``R_g = R_sim`` (the paper's ``R(a_t, s_{t+1})`` uses the agent's
    action and the grounded next state).

    Args:
        G: ``(S, A, A)`` action-transformer distribution from :func:`action_transformer`.

    Raises:
        ValueError: if ``G`` has the wrong shape or its rows are not distributions.
    """
    G = np.asarray(G, dtype=float)
    if G.shape != (sim.n_states, sim.n_actions, sim.n_actions):
        raise ValueError(f"G must have shape {(sim.n_states, sim.n_actions, sim.n_actions)}")
    if np.any(G < 0) or not np.allclose(G.sum(-1), 1.0):
        raise ValueError("every row G[s, a, :] must be a distribution over sim actions")
    P = np.einsum("sab,sbt->sat", G, sim.P)
    return TabularMDP(P, sim.R, sim.terminal, sim.start, sim.state_names, sim.action_names,
                      name or f"grounded {sim.name}")


# --------------------------------------------------------------------------------------------
# Vectorised rollouts on an MDP
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class RolloutResult:
    """``returns (N,)`` undiscounted, ``lengths (N,)`` steps, ``truncated (N,)`` bool (hit the
    step cap), and when recorded the transitions ``s, a, s2`` (``(M,)`` int each)."""

    returns: np.ndarray
    lengths: np.ndarray
    truncated: np.ndarray
    s: np.ndarray | None = None
    a: np.ndarray | None = None
    s2: np.ndarray | None = None


def rollout(
    mdp: TabularMDP,
    policy: np.ndarray,
    n_episodes: int,
    rng: np.random.Generator,
    *,
    max_steps: int = 1000,
    explore: float = 0.0,
    record: bool = False,
) -> RolloutResult:
    """Run ``n_episodes`` episodes at once (NumPy, one array operation per time step).

    Every step draws one uniform number per episode (for all episodes, running or not), so
    two policies rolled out from identically seeded generators share their random numbers
    (common random numbers): where they act alike, their episodes are identical. With
    ``explore > 0`` the action is replaced by a uniformly random one with that probability
    (ε-greedy behaviour policy), drawn from the same generator. Episodes still running after
    ``max_steps`` steps are truncated and keep the return accumulated so far.

    Args:
        mdp: the environment.
        policy: ``(S,)`` int.
        n_episodes: number of episodes (> 0).
        rng: the random generator (consumed).
        max_steps: step cap per episode (> 0).
        explore: ε in [0, 1].
        record: also return every transition.

    Raises:
        ValueError: for a bad policy, ``n_episodes <= 0``, ``max_steps <= 0`` or ε outside [0, 1].
    """
    pi = _as_policy(mdp, policy)
    n = int(n_episodes)
    if n <= 0:
        raise ValueError(f"n_episodes must be positive, got {n_episodes}")
    if int(max_steps) <= 0:
        raise ValueError(f"max_steps must be positive, got {max_steps}")
    if not 0.0 <= explore <= 1.0:
        raise ValueError(f"explore must be in [0, 1], got {explore}")
    cdf = np.cumsum(mdp.P, axis=-1)
    cdf[..., -1] = 1.0
    s = np.full(n, mdp.start, dtype=np.intp)
    returns = np.zeros(n)
    lengths = np.zeros(n, dtype=np.int64)
    active = ~mdp.terminal[s]
    rec: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    for _ in range(int(max_steps)):
        if not active.any():
            break
        u = rng.random(n)
        a = pi[s]
        if explore > 0:
            swap = rng.random(n) < explore
            a = np.where(swap, rng.integers(mdp.n_actions, size=n), a)
        i = np.flatnonzero(active)
        si, ai = s[i], a[i]
        s2 = (cdf[si, ai] <= u[i, None]).sum(-1)
        returns[i] += mdp.R[si, ai, s2]
        lengths[i] += 1
        if record:
            rec.append((si, ai, s2))
        s[i] = s2
        active[i] = ~mdp.terminal[s2]
    out = dict(returns=returns, lengths=lengths, truncated=active.copy())
    if record:
        cat = (lambda k: np.concatenate([r[k] for r in rec]) if rec else np.zeros(0, np.intp))
        out.update(s=cat(0), a=cat(1), s2=cat(2))
    return RolloutResult(**out)


@dataclass(frozen=True)
class EvalResult:
    """Monte-Carlo estimate of a policy's expected return: ``mean``, standard error ``se``
    (sample std / √n, reward units), ``n`` episodes, ``truncated`` = episodes cut at the cap."""

    mean: float
    se: float
    n: int
    truncated: int


def evaluate_policy(
    mdp: TabularMDP,
    policy: np.ndarray,
    n_episodes: int = 10_000,
    rng: np.random.Generator | int | None = 0,
    *,
    max_steps: int = 1000,
) -> EvalResult:
    """Expected return of ``policy`` on ``mdp`` from ``n_episodes`` vectorised episodes.

    The paper's protocol (§IV.A): "we estimate the expected return from averaging 10,000
    episodes". ``rng`` may be a Generator or a seed; see :func:`rollout` for common random
    numbers and the step cap.

    Raises:
        ValueError: as :func:`rollout`.
    """
    gen = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    res = rollout(mdp, policy, n_episodes, gen, max_steps=max_steps)
    n = res.returns.size
    se = float(res.returns.std(ddof=1) / np.sqrt(n)) if n > 1 else float("nan")
    return EvalResult(float(res.returns.mean()), se, n, int(res.truncated.sum()))


# --------------------------------------------------------------------------------------------
# The grounding loop (Algorithm 1)
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class GroundingResult:
    """Result of :func:`ground`.

    Attributes:
        policy: ``(S,)`` int, the final policy (optimal in the last grounded sim).
        initial_policy: ``(S,)`` int, the policy trained in the ungrounded sim.
        grounded: the last grounded MDP.
        model: the last real forward model.
        steps: grounding steps run.
        converged: True if the policy stopped changing before ``max_grounding_steps``.
        real_transitions: real transitions collected in total.
        history: number of states whose action changed at each grounding step.
    """

    policy: np.ndarray
    initial_policy: np.ndarray
    grounded: TabularMDP
    model: ForwardModel
    steps: int
    converged: bool
    real_transitions: int
    history: list[int] = field(default_factory=list)


def ground(
    sim: TabularMDP,
    real: TabularMDP,
    method: Method,
    rng: np.random.Generator,
    *,
    real_episodes: int = 10_000,
    max_grounding_steps: int = 30,
    patience: int = 2,
    explore: float = 0.1,
    min_count: float = 1,
    accumulate: bool = True,
    max_steps: int = 1000,
    policy0: np.ndarray | None = None,
) -> GroundingResult:
    """GAT or SGAT on a finite MDP: Algorithm 1 of the paper with tabular models.

    Starts from the policy that is optimal in the ungrounded sim (or ``policy0``). Each
    grounding step: run ``real_episodes`` real episodes with the ε-greedy current policy
    (``explore``), update the counted forward model ``f_real`` (data accumulate over steps
    unless ``accumulate`` is False), build the action transformer with the exact sim inverse
    model, and re-solve the grounded MDP by policy iteration (the paper's policy improvement
    "using policy iteration", §IV.A). Stops when the policy is unchanged for ``patience``
    consecutive steps ("repeated until convergence") or after ``max_grounding_steps``.

    Args:
        sim: the deterministic simulator.
        real: the real environment (only sampled, never read).
        method: ``"gat"`` (most likely next state) or ``"sgat"`` (sampled next state).
        rng: generator for the real episodes.

    Returns:
        :class:`GroundingResult`.

    Raises:
        ValueError: for mismatched MDPs, a stochastic sim or bad parameters.
    """
    if sim.P.shape != real.P.shape or sim.start != real.start:
        raise ValueError("sim and real must share states, actions and start state")
    if real_episodes <= 0 or max_grounding_steps <= 0 or patience <= 0:
        raise ValueError("real_episodes, max_grounding_steps and patience must be positive")
    sim.next_state()  # raises for a stochastic sim
    pi = policy_iteration(sim, policy0).policy
    initial = pi.copy()
    S, A = sim.n_states, sim.n_actions
    st = {"counts": np.zeros((S, A, S), dtype=np.int64), "total": 0, "unchanged": 0, "history": [],
          "model": ForwardModel.from_counts(np.zeros((S, A, S), dtype=np.int64)), "grounded": sim}

    def ground_step(i, policy):  # real episodes with π_i, counted forward model, grounded MDP
        data = rollout(real, policy, real_episodes, rng, max_steps=max_steps, explore=explore, record=True)
        new_counts = count_transitions(S, A, data.s, data.a, data.s2)
        st["counts"] = st["counts"] + new_counts if accumulate else new_counts
        st["total"] += int(data.s.size)
        st["model"] = ForwardModel.from_counts(st["counts"])
        G = action_transformer(sim, st["model"], method, min_count=min_count)
        st["grounded"] = grounded_mdp(sim, G, name=f"{method.upper()}-grounded {sim.name}")
        return st["grounded"]

    def evaluate(i, new_pi, progress):  # how many states changed their action
        changed = int(np.sum(new_pi != progress["policy"]))
        st["history"].append(changed)
        st["unchanged"] = st["unchanged"] + 1 if changed == 0 else 0

    prog = grounding_loop(new_progress(pi), max_grounding_steps, ground=ground_step,
                          improve=lambda i, policy, grounded, progress: policy_iteration(grounded, policy).policy,
                          evaluate=evaluate, stop=lambda i, progress: st["unchanged"] >= patience)
    converged = st["unchanged"] >= patience
    return GroundingResult(prog["policy"], initial, st["grounded"], st["model"], prog["step"] - 1, converged,
                           st["total"], st["history"])
