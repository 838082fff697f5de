"""Grounding works where it should: a sim-made "real" with a known joint-level difference."""

import numpy as np
import pytest

from envs import SimWorld
from envs.wrappers import ActionMismatch
from sgat.grounding import Transitions, fit_transformer, trajectory_transitions
from experiments.runtime.grounding import grounding_spec
from sgat.transformer import GroundedEnv


def random_leg_commands(robot, n, rng, amp=0.15):
    """Smooth random leg targets around the crouch: three sines per joint, 0.3-3 Hz."""
    q0 = robot.pose("crouch", actuated=True)
    t = np.arange(n) * 0.01
    A = np.repeat(q0[None], n, 0)
    for i, j in enumerate(robot.actuated_joint_names):
        if j in robot.groups["legs"]:
            for _ in range(3):
                A[:, i] += amp / 3 * np.sin(2 * np.pi * rng.uniform(0.3, 3.0) * t + rng.uniform(0, 2 * np.pi))
    return np.clip(A, robot.lower[robot.actuated_index] + 0.01, robot.upper[robot.actuated_index] - 0.01)


def run(env, A, seed, noise=0.0, rng=None):
    obs, _ = env.reset(seed=seed)
    O, AP = [], []
    for a in A:
        ap = a + rng.normal(0, noise, a.shape) if noise else a
        O.append(obs)
        AP.append(ap)
        obs, *_ = env.step(ap)
    return np.array(O), np.array(AP)


def step_from(env, obs, a):
    """One control step of ``env`` (a fixed-base NAO, possibly wrapped) from observation ``obs``."""
    base = env.unwrapped
    base.set_state(obs[base.layout["q"]], obs[base.layout["dq"]])
    base._last_obs = obs
    return env.step(a)[0]


@pytest.fixture(scope="module")
def pair():
    sim = SimWorld(fixed_base=True)
    spec = grounding_spec(sim)
    robot = sim.robot
    q0 = robot.pose("crouch", actuated=True)
    real = ActionMismatch(SimWorld(fixed_base=True), gain=0.7, offset=0.05, noise_std=0.03,
                          index=spec.action_index, reference=q0, seed=0)
    rng = np.random.default_rng(0)
    R, S = [], []
    for ep in range(4):
        A = random_leg_commands(robot, 500, rng)
        O, _ = run(real, A, ep)
        R.append(trajectory_transitions(O, A, spec))  # the commanded action: noise is real dynamics
        O, AP = run(sim, A, ep, noise=0.1, rng=rng)  # exploration noise for the inverse model
        S.append(trajectory_transitions(O, AP, spec))
    real_tr, sim_tr = Transitions.concat(R), Transitions.concat(S)
    fits = {m: fit_transformer(real_tr, sim_tr, spec, method=m, alpha=1.0, seed=0, fit_kwargs={"lr": 3e-3})
            for m in ("sgat", "gat")}
    A = random_leg_commands(robot, 300, np.random.default_rng(99))
    O, _ = run(real, A, 123)  # held-out real trajectory
    return sim, real, spec, fits, O, A, real_tr.dS.std(0)


def _grounded_next(sim, spec, transformer, obs, a):
    ap = a.copy()
    ap[spec.action_index] = transformer.transform(spec.states(obs), a[spec.action_index])
    return spec.states(step_from(sim, obs, ap))


def test_grounding_halves_one_step_error(pair):
    """Error of the expected next state (20 draws each), in units of the real Δs spread."""
    sim, real, spec, fits, O, A, scale = pair
    err = {"none": [], "sgat": [], "gat": []}
    for t in range(5, 295, 15):
        real_mean = np.mean([spec.states(step_from(real, O[t], A[t])) for _ in range(20)], 0)
        err["none"].append(np.linalg.norm((spec.states(step_from(sim, O[t], A[t])) - real_mean) / scale))
        for m in ("sgat", "gat"):
            g = np.mean([_grounded_next(sim, spec, fits[m].transformer, O[t], A[t]) for _ in range(20)], 0)
            err[m].append(np.linalg.norm((g - real_mean) / scale))
    e = {k: float(np.mean(v)) for k, v in err.items()}
    assert e["sgat"] <= 0.5 * e["none"], e
    assert e["gat"] <= 0.5 * e["none"], e


def test_only_sgat_reproduces_the_real_spread(pair):
    sim, real, spec, fits, O, A, _ = pair
    ratio = {"sgat": [], "gat": []}
    for t in range(20, 280, 50):
        real_std = np.std([spec.states(step_from(real, O[t], A[t])) for _ in range(40)], 0).mean()
        for m in ("sgat", "gat"):
            g = np.std([_grounded_next(sim, spec, fits[m].transformer, O[t], A[t]) for _ in range(40)], 0).mean()
            ratio[m].append(g / real_std)
    assert abs(np.mean(ratio["sgat"]) - 1) <= 0.25, ratio
    assert np.mean(ratio["gat"]) < 0.05, ratio  # GAT's grounded sim is deterministic


def test_grounded_env_records_command_and_applied(pair):
    sim, _, spec, fits, O, A, _ = pair
    env = GroundedEnv(SimWorld(fixed_base=True), fits["sgat"].transformer)
    obs, _ = env.reset(seed=0)
    a = A[0].copy()
    keep = a.copy()
    _, _, _, _, info = env.step(a)
    assert np.array_equal(a, keep)  # the agent's array is not modified
    assert np.array_equal(info["commanded_action"], keep)
    arms = np.setdiff1d(np.arange(len(a)), spec.action_index)
    assert np.array_equal(info["applied_action"][arms], a[arms])  # arms and head pass through
    assert not np.allclose(info["applied_action"][spec.action_index], a[spec.action_index])


def test_action_mismatch_copies_and_applies():
    env = ActionMismatch(SimWorld(fixed_base=True), gain=0.5, offset=0.1, index=[0], seed=0)
    env.reset(seed=0)
    a = env.unwrapped.robot.pose("crouch", actuated=True).copy()
    a[0] = 0.4
    keep = a.copy()
    _, _, _, _, info = env.step(a)
    assert np.array_equal(a, keep)
    assert info["applied_action"][0] == pytest.approx(0.5 * 0.4 + 0.1)
    assert np.array_equal(info["applied_action"][1:], a[1:])


def _damped_world(damping: float = 0.3):
    """A fixed-base NAO sim with viscous damping [N m s/rad] in its leg joints (the sim has none):
    the "real" world of the DAD tests (its applied actions are its commands, as the real world's are)."""
    real = SimWorld(fixed_base=True)
    m = real.model
    for j in real.robot.groups["legs"]:
        m.dof_damping[m.jnt_dofadr[m.joint(j).id]] = damping
    return real


@pytest.mark.parametrize("latency, delay", [(0.0237, 2), (0.0165, 1), (0.0099, 0), (None, 0)])
def test_identified_delay_is_the_latency_in_whole_control_steps(tmp_path, latency, delay):
    """Hybrid grounding's ``delay=auto``: the identified latency floored to control steps (10 ms); no
    latency term, no delay."""
    import json

    from experiments.runtime.grounding import identified_delay

    model = {"pd_gain[RAnklePitch]": 0.9, **({"latency": latency} if latency is not None else {})}
    path = tmp_path / "report.json"
    path.write_text(json.dumps({"model": model, "effects": []}))
    assert identified_delay([str(path)]) == delay
