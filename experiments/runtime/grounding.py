"""The grounding step for the walking NAO, shared by ``optimize`` and ``fidelity``.

One place decides how a grounding step turns walks into an action transformer (Algorithm 1 of
Desai et al., IROS 2020): which observation entries are the grounding state (:func:`nao_spec`),
how the forward and inverse models are fitted (:class:`sgat.grounding.GroundingConfig`), and the
defaults a user gets (:data:`DEFAULT_GROUNDING`). ``sgatwalk optimize`` and ``sgatwalk fidelity``
call :func:`fit_nao_grounding` with the same settings, so what the fidelity table measures is what
the optimizer trains in.
"""

from __future__ import annotations

import dataclasses
import functools
import math

from common.defaults import CONTROL_DT
from robots import get_robot
from sgat.grounding import (GroundingConfig, GroundingFit, Transitions, dad_transitions, fit_grounding,
                           recording_transitions)
from sgat.transformer import GroundingSpec

#: Real walks of θ_i per grounding step, sim walks with exploration noise, and that noise [rad]
#: (the standard deviation of Gaussian noise on the 11 leg targets of the sim walks). 0.02 rad, not
#: 0.05: with 0.05 the sim walks of θ0 fall after ~2.5 s, so the inverse model never sees a steady
#: gait (``sgatwalk fidelity`` on development seeds, README "sgatwalk fidelity").
REAL_WALKS = 4
SIM_WALKS = 4
EXPLORATION_NOISE = 0.02
#: The grounding that ``optimize`` and ``fidelity`` use unless told otherwise: SGAT with α = 0.5 (the
#: GAT/GARAT code's blend), an ensemble of 5 forward/inverse pairs (one drawn per episode) and
#: *linear* forward and inverse models (``hidden=()``: the MLP's linear path alone, not the paper's
#: 64×64 tanh networks). On the development panel a single fit's fitness bias spread over 11 points
#: across draws of its 4 real walks, the ensemble's over 1 point; linear models raised SGAT's rank
#: correlation with real fitness from 0.39 to 0.59 (worst draw 0.30 to 0.53) and, on the held-out
#: panel, its bias from +3.0 to +0.4 and its Brier score from 0.31 to 0.23; the Table I run with linear
#: models found better real gaits for SGAT and GAT at both grounding steps (README "sgatwalk fidelity",
#: "sgatwalk table1"). A tanh network fitted on the states of one gait extrapolates unpredictably to
#: the states of the gaits CMA-ES tries; a linear map extrapolates predictably.
DEFAULT_GROUNDING = GroundingConfig(alpha=0.5, method="sgat", ensemble=5, hidden=())
#: Frames of state history the forward and inverse models see (``s_{t-5}, ..., s_t`` at the 100 Hz
#: control rate: 50 ms). The paper's models see s_t alone, which cannot tell where a joint is headed.
#: Measured with ``sgatwalk fidelity`` against one frame on three panels (README "sgatwalk fidelity",
#: third round: the held-out panel walked on two machines, the development panel on one): SGAT's
#: median Spearman rho 0.33 -> 0.39, 0.59 -> 0.58, 0.25 -> 0.27 and its worst draw better on all three
#: (0.09 -> 0.28, 0.48 -> 0.51, 0.12 -> 0.13); GAT ranked better on two of the three, and SGAT's fall
#: forecast (Brier score) improved on two. The previous commands as extra inputs
#: (``GroundingConfig.command_history = 3``) on top of six frames did better still on both panels of
#: one machine, but CMA-ES in that world found no better real gaits (SGAT-only Table I, paired with
#: the six-frame run: +0.3 and -1.9 fitness points at the two grounding steps, p = 0.84 and 0.29).
DEFAULT_HISTORY = 6
#: Hybrid grounding (SGAT on top of the identified sim): the same models, blended at α = 0.1. The
#: identified sim already ranks gaits well; every larger α tried made the ranking worse.
HYBRID_GROUNDING = dataclasses.replace(DEFAULT_GROUNDING, alpha=0.1)
#: Wall-clock time budget [s] of each diagnosis of the real world's identification (the identified
#: and hybrid worlds: ``experiments.runtime.identify.identify_real``), in ``optimize`` and ``fidelity`` alike:
#: a safety net, not a setting of the result. A budget that binds stops the diagnosis early, so the
#: identified world then depends on the machine's speed: with 60 s, one draw's fixed-base diagnosis
#: ran out on a machine 1.4 times slower than the one of the README's default fidelity run, and a
#: stepping diagnosis that runs out before its uneven-ground stage leaves the ground out. The
#: stepping diagnoses of Table I's optimization seeds 0-2 take 40-41 s on the faster of the README's two
#: machines and about twice that on the slower, where 60 s may have stopped them early.
IDENTIFY_BUDGET_S = 180.0
#: Screen/refit rounds of each diagnosis of the real world's identification (the identified and hybrid
#: worlds; ``experiments.runtime.identify.identify_real``'s ``rounds``), in ``optimize`` and ``fidelity`` alike.
#: The first round finds what walking feels most (the actuation latency and the wrists' friction in
#: the air, the contact and the uneven ground on the floor); the in-air stage's second round adds the
#: friction of the elbows, the head and a shoulder, and costs more time than the first
#: (``benchmarks/bench_diagnose_rounds.py``: one set of logs' in-air diagnosis took 45 s in two rounds
#: and 9 s in one, the whole identification 122 s and 80 s, slower machine kind). One round was tried as the
#: default in the twenty-fourth round and left as an option (``--identify-rounds 1``): without the arm
#: terms the fitted latency absorbs their effect (0.7-4.3 ms higher on 9 of 10 draws, the same on the
#: tenth, where the real world's lies in 10-20 ms and two rounds already read 16.5-24.5 ms), and on a
#: held-out panel the hybrid world ranked the gaits worse beyond that panel's noise (README,
#: twenty-fourth round).
IDENTIFY_ROUNDS = 2


#: Grounding states of the NAO: what it measures of its legs (encoder angles and joint velocities),
#: optionally with the inertial unit (gyro and torso roll/pitch).
GROUNDING_STATES = ("legs", "legs+imu")


def grounding_spec(env, state: str = "legs", history: int = 1) -> GroundingSpec:
    """The grounding spec of a world (``envs.NaoEnv`` or a wrapper of one): the state is ``q.*`` and
    ``dq.*`` of the 12 leg joints (``"legs+imu"``: plus ``gyro.*``, ``angle.roll``, ``angle.pitch``),
    the grounded actions are the actuated leg targets (the NAO: 11, its shared HipYawPitch counts
    once; G1, Talos: 12); arms, waist and head pass through.

    Raises:
        ValueError: unknown state variant, or history < 1.
    """
    if state not in GROUNDING_STATES:
        raise ValueError(f"unknown grounding state {state!r}; choose one of {', '.join(GROUNDING_STATES)}")
    base = env.unwrapped
    robot = base.robot
    legs = robot.groups["legs"]
    names = [f"q.{j}" for j in legs] + [f"dq.{j}" for j in legs]
    if state == "legs+imu":
        names += ["gyro.x", "gyro.y", "gyro.z", "angle.roll", "angle.pitch"]
    acts = list(robot.actuated_joint_names)
    return GroundingSpec.from_names(base.layout.names, names, acts, [j for j in acts if j in legs],
                                    base.action_space.low, base.action_space.high, history,
                                    f"{'nao' if robot.name == 'nao_h25' else robot.name}-{state}")


@functools.lru_cache(maxsize=8)
def nao_spec(state: str = "legs", history: int = 1, robot: str = "nao") -> GroundingSpec:
    """The grounding spec (:func:`grounding_spec`) of the MuJoCo sim of ``robot`` (a
    ``robots.get_robot`` name; default the NAO)."""
    from envs import NaoSimEnv  # lazy: loads the engines

    env = NaoSimEnv(get_robot(robot))
    try:
        return grounding_spec(env, state, history)
    finally:
        env.close()


def fit_nao_grounding(real_recs, sim_recs, cfg: GroundingConfig, *, state: str = "legs", history: int = 1,
                      seed: int = 0, robot: str = "nao", base_env=None, map_fn=None) -> GroundingFit:
    """Fit the action transformer of a grounding step on NAO walk recordings.

    Args:
        real_recs: ``envs.Recording`` walks in the real world (commanded actions).
        sim_recs: walks in the sim the transformer will ground, with exploration noise on the
            applied leg targets (``app`` columns) and the clean commands (``cmd``).
        cfg: the model settings; ``state``/``history``: the grounding state (:func:`nao_spec`).
        robot: the robot the recordings are of (``robots.get_robot`` name; default the NAO).
        seed: seed of the fits.
        base_env: the sim the transformer grounds (an ``envs`` world of ``robot``), needed when
            ``cfg.dad_iterations`` > 0: each round the grounded sim replays every real walk's
            commands from its seed (``envs.rollout.CommandLog``), the states it reaches become forward
            model rows labelled with the real walk's next states
            (:func:`sgat.grounding.dad_transitions`; Data as Demonstrator, Venkatraman et al., AAAI
            2015), and the forward models are refitted on the real rows and every round's DAD rows.
        map_fn: fits the ensemble's members side by side (:func:`sgat.grounding.fit_grounding`'s
            ``map_fn``, e.g. an executor's ``map``); the fit does not depend on it.

    Raises:
        KeyError: a recording lacks an observation column. ValueError: unusable data, or DAD rounds
            without ``base_env``.
    """
    from envs import ObservationLayout  # lazy: loads the engines

    if cfg.dad_iterations and base_env is None:
        raise ValueError("dad_iterations > 0 needs the sim the transformer grounds (base_env)")
    spec = nao_spec(state, history, robot)
    layout = ObservationLayout(get_robot(robot))
    c, d = cfg.forward_commands, int(cfg.delay)
    real = recording_transitions(real_recs, layout, spec, c, d)
    sim = recording_transitions(sim_recs, layout, spec, c, d)
    fit = fit_grounding(real, sim, spec, cfg, seed=seed, map_fn=map_fn)
    extra = []
    for _ in range(int(cfg.dad_iterations)):
        from envs.rollout import CommandLog, rollout  # lazy: loads the engines
        from sgat.transformer import GroundedEnv  # lazy: sgat loads torch

        env = GroundedEnv(base_env, fit.transformer)
        replays = [rollout(env, CommandLog(r.group("cmd")), seed=int(r.meta.get("seed", 0)),
                           seconds=len(r) * float(r.meta["control_dt"])) for r in real_recs]
        extra.append(dad_transitions(replays, real_recs, layout, spec, c))
        fit = fit_grounding(real, sim, spec, cfg, seed=seed, forward_extra=Transitions.concat(extra), previous=fit,
                            map_fn=map_fn)
    return fit


def identified_delay(reports, control_dt: float = CONTROL_DT) -> int:
    """The delay d [control steps] that hybrid grounding's models bridge for an identified sim: its
    identified actuation latency L (MuJoCo ``actuator_delay``, a continuous delay) in whole control
    steps, d = floor(L / Δt). A command given at step t reaches the identified sim's actuators at
    t·Δt + L, within control step t + d, so s_{t+1}, ..., s_{t+d} hold nothing of it and s_{t+d+1} is
    the first state it moves (measured: :func:`sgat.grounding.command_visibility` on the default
    fidelity run's grounding walks finds R² ≈ 0 at lead 1 on every draw, its best lead at d + 1 for
    latencies of 16.5-17.1 ms (d = 1) and 23.2-23.7 ms (d = 2); README, twenty-sixth round).

    Args:
        reports: the identification's ``report.json`` paths (``experiments.runtime.identify.identify_real``).
        control_dt: the control period [s].

    Returns:
        d >= 0 (0 when no latency was identified).

    Raises:
        FileNotFoundError, ValueError: what :func:`sysid.identified.load_identified` raises.
    """
    return max(0, int(math.floor(identified_latency(reports) / control_dt + 1e-9)))


def identified_latency(reports) -> float:
    """The actuation latency [s] an identification found (``latency`` of
    :func:`sysid.identified.load_identified`, later reports overriding earlier ones); 0 when none.

    Raises:
        FileNotFoundError, ValueError: what :func:`sysid.identified.load_identified` raises.
    """
    from sysid.identified import load_identified  # lazy: loads the engines

    terms, _ = load_identified(reports)
    return next((float(v) for t, v in terms.items() if t.label() == "latency"), 0.0)
