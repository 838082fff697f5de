"""The grounding step for a walking humanoid, shared by ``optimize`` and ``fidelity``.

One place decides how a grounding step turns walks into an action transformer (Algorithm 1 of
Desai et al., IROS 2020): which observation entries are the grounding state (:func:`grounding_spec`)
and how the forward and inverse models are fitted (:class:`sgat.grounding.GroundingConfig`, built
from a training world's options by :meth:`experiments.runtime.worlds.WorldSpec.grounding_config`).
``sgatwalk optimize`` and ``sgatwalk fidelity`` call :func:`fit_walk_grounding` with the same
settings, so what the fidelity table measures is what the optimizer trains in.
"""

from __future__ import annotations

import functools
import math

from common.defaults import CONTROL_DT
from robots import get_robot
from sgat.grounding import GroundingConfig, GroundingFit, fit_grounding, recording_transitions
from sgat.transformer import GroundingSpec

#: Wall-clock time budget [s] of each diagnosis of the real world's identification (the identified
#: and hybrid worlds: :func:`experiments.runtime.identify.identify_real`), a safety net, not a setting
#: of the result: a budget that binds stops the diagnosis early, so the identified world then depends
#: on the machine's speed (the identification's log line warns when it does).
IDENTIFY_BUDGET_S = 180.0
#: Screen/refit rounds of each diagnosis of the real world's identification: the first round finds
#: what walking feels most (the actuation latency, the wrists' friction in the air; the contact and
#: the uneven ground on the floor), the second adds the friction of the elbows, the head and a
#: shoulder; with one round the fitted latency absorbs those (docs/decisions.md).
IDENTIFY_ROUNDS = 2


def grounding_spec(env, history: int = 1) -> GroundingSpec:
    """The grounding spec of a world (an ``envs`` world or a wrapper of one): the state is what the
    robot measures of its legs, ``q.*`` and ``dq.*`` of the leg joints, over ``history`` frames; the
    grounded actions are the actuated leg targets (the NAO: 11, its shared HipYawPitch counts once;
    G1, Talos: 12); arms, waist and head pass through.

    Raises:
        ValueError: history < 1.
    """
    base = env.unwrapped
    robot = base.robot
    legs = robot.groups["legs"]
    names = list(base.layout.columns("q", legs) + base.layout.columns("dq", legs))
    acts = list(robot.actuated_joint_names)
    return GroundingSpec.from_names(base.layout.names, names, acts, [j for j in acts if j in legs],
                                    base.action_space.low, base.action_space.high, history, f"{robot.name}-legs")


@functools.lru_cache(maxsize=8)
def walk_spec(history: int = 1, robot: str = "nao") -> GroundingSpec:
    """The grounding spec (:func:`grounding_spec`) of the MuJoCo sim of ``robot`` (a
    ``robots.get_robot`` name)."""
    from envs import SimWorld  # lazy: loads the engines

    env = SimWorld(get_robot(robot))
    try:
        return grounding_spec(env, history)
    finally:
        env.close()


def fit_walk_grounding(real_recs, sim_recs, cfg: GroundingConfig, *, history: int = 1, seed: int = 0,
                       robot: str = "nao", map_fn=None) -> GroundingFit:
    """Fit the action transformer of a grounding step on walk recordings.

    Args:
        real_recs: ``envs.Recording`` walks in the real world (commanded actions).
        sim_recs: walks in the sim the transformer will ground, with exploration noise on the
            applied leg targets (``app`` columns) and the clean commands (``cmd``).
        cfg: the model settings; ``history``: frames of grounding state the models see (:func:`walk_spec`).
        seed: seed of the fits.
        robot: the robot the recordings are of (``robots.get_robot`` name).
        map_fn: fits the ensemble's members side by side (:func:`sgat.grounding.fit_grounding`'s
            ``map_fn``, e.g. an executor's ``map``); the fit does not depend on it.

    Raises:
        KeyError: a recording lacks an observation column. ValueError: unusable data.
    """
    from envs import ObservationLayout  # lazy: loads the engines

    spec = walk_spec(history, robot)
    layout = ObservationLayout(get_robot(robot))
    d = int(cfg.delay)
    real = recording_transitions(real_recs, layout, spec, d, d)
    sim = recording_transitions(sim_recs, layout, spec, d, d)
    return fit_grounding(real, sim, spec, cfg, seed=seed, map_fn=map_fn)


def identified_delay(reports, control_dt: float = CONTROL_DT) -> int:
    """The delay d [control steps] that hybrid grounding's models bridge for an identified sim: its
    identified actuation latency L (MuJoCo ``actuator_delay``, a continuous delay) in whole control
    steps, d = floor(L / Δt). A command given at step t reaches the identified sim's actuators at
    t·Δt + L, within control step t + d, so s_{t+1}, ..., s_{t+d} hold nothing of it and s_{t+d+1} is
    the first state it moves (:func:`sgat.grounding.command_visibility` measures it on walks).

    Args:
        reports: the identification's ``report.json`` paths (:func:`experiments.runtime.identify.identify_real`).
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


__all__ = ["IDENTIFY_BUDGET_S", "IDENTIFY_ROUNDS", "fit_walk_grounding", "grounding_spec", "identified_delay",
           "identified_latency", "walk_spec"]
