"""The gym "real" variants: action noise on a copy (the in-place trap), mass changes on the model."""

import numpy as np
import pytest

from experiments.gym.envs import GaussianActionNoise, body_names, make_env, scale_body_masses, set_state_from_obs


def _ip_nominal():
    env = make_env("InvertedPendulum")
    m = env.unwrapped.model
    return m.body_mass.copy(), m.body_inertia.copy()


def test_noise_never_alters_the_logged_action():
    env = make_env("InvertedPendulum", heavy=True, noise=0.3)
    assert isinstance(env, GaussianActionNoise)
    env.reset(seed=1)
    batch = np.array([[0.7], [-0.2]])  # a vectorised trainer's batch; the per-env action is a view
    logged = batch.copy()
    obs, r, term, trunc, info = env.step(batch[0])
    assert np.array_equal(batch, logged), "the noise wrapper modified the agent's array in place"
    assert np.array_equal(info["commanded_action"], logged[0])
    assert not np.array_equal(info["applied_action"], logged[0])
    # float32 arrays (what SB3 hands over) too
    a32 = np.array([1.5], dtype=np.float32)
    env.step(a32)
    assert a32[0] == np.float32(1.5)


def test_noise_inside_a_vec_env_keeps_the_collectors_actions():
    from stable_baselines3.common.vec_env import DummyVecEnv

    venv = DummyVecEnv([lambda: make_env("InvertedPendulum", noise=0.5), lambda: make_env("InvertedPendulum", noise=0.5)])
    venv.seed(3)
    venv.reset()
    actions = np.array([[0.25], [-0.25]], dtype=np.float32)
    kept = actions.copy()
    venv.step(actions)
    assert np.array_equal(actions, kept)


def test_noise_size_clipping_and_reproducibility():
    env = make_env("InvertedPendulum", noise=0.1)  # half-range 3 -> std 0.3
    env.reset(seed=0)
    a = np.zeros(1)
    d = np.array([env.perturb(a)[0] for _ in range(4000)])
    assert abs(d.std() - 0.3) < 0.02 and abs(d.mean()) < 0.03
    top = np.array([env.perturb(np.array([3.0]))[0] for _ in range(200)])
    assert top.max() <= 3.0 and top.min() < 3.0  # clipped to the bounds
    # seeded resets reproduce the noise; unseeded resets continue the stream (no replay per episode)
    env.reset(seed=5)
    first = [env.perturb(a)[0] for _ in range(5)]
    env.reset()
    second = [env.perturb(a)[0] for _ in range(5)]
    env.reset(seed=5)
    again = [env.perturb(a)[0] for _ in range(5)]
    assert first == again and first != second
    with pytest.raises(ValueError):
        make_env("InvertedPendulum", noise=-0.1)
    with pytest.raises(ValueError):
        GaussianActionNoise(make_env("InvertedPendulum"), float("nan"))


def test_noise_zero_is_the_plain_env_and_control_cost_uses_the_command():
    assert not isinstance(make_env("InvertedPendulum", noise=0.0), GaussianActionNoise)
    env = make_env("HalfCheetah", noise=0.5)
    env.reset(seed=0)
    a = np.full(6, 0.5)
    _, _, _, _, info = env.step(a)
    assert info["reward_ctrl"] == pytest.approx(-0.1 * np.sum(a ** 2))
    assert not np.allclose(info["applied_action"], a)


def test_pendulum_pole_is_ten_times_heavier_by_default():
    mass0, inertia0 = _ip_nominal()
    env = make_env("InvertedPendulum", heavy=True)
    m = env.unwrapped.model
    names = body_names(env)
    pole, cart = names.index("pole"), names.index("cart")
    assert m.body_mass[pole] == pytest.approx(10 * mass0[pole])
    assert np.allclose(m.body_inertia[pole], 10 * inertia0[pole])
    assert m.body_mass[cart] == pytest.approx(mass0[cart]) and np.allclose(m.body_inertia[cart], inertia0[cart])
    assert m.body_subtreemass[pole] == pytest.approx(10 * mass0[pole])  # mj_setConst ran
    change = env.unwrapped.sgat_mass_change
    assert change["bodies"] == ["pole"] and change["factor"] == 10
    m20 = make_env("InvertedPendulum", heavy=True, pole_factor=20).unwrapped.model
    assert m20.body_mass[pole] == pytest.approx(20 * mass0[pole])  # the GARAT code's ≈100 kg pole
    # the sim itself is untouched
    assert make_env("InvertedPendulum").unwrapped.model.body_mass[pole] == pytest.approx(mass0[pole])


def test_cheetah_is_43_percent_heavier():
    sim = make_env("HalfCheetah").unwrapped.model
    real = make_env("HalfCheetah", heavy=True).unwrapped.model
    assert sim.body_mass.sum() == pytest.approx(14.0)
    assert real.body_mass.sum() == pytest.approx(20.0)
    assert np.allclose(real.body_mass[1:], sim.body_mass[1:] * 20 / 14)
    assert np.allclose(real.body_inertia[1:], sim.body_inertia[1:] * 20 / 14)
    assert real.body_subtreemass[1] == pytest.approx(20.0)


def test_mass_change_changes_the_dynamics_and_bad_inputs_fail():
    sim, real = make_env("InvertedPendulum"), make_env("InvertedPendulum", heavy=True)
    o1, _ = sim.reset(seed=0)
    o2, _ = real.reset(seed=0)
    assert np.array_equal(o1, o2)  # same reset seed -> same initial state
    n1, n2 = sim.step(np.array([2.0]))[0], real.step(np.array([2.0]))[0]
    assert not np.allclose(n1, n2)
    with pytest.raises(ValueError, match="unknown body"):
        scale_body_masses(make_env("InvertedPendulum"), 2.0, ["mast"])
    with pytest.raises(ValueError, match="positive"):
        scale_body_masses(make_env("InvertedPendulum"), 0.0)
    with pytest.raises(ValueError, match="unknown --env"):
        make_env("Hopper")


@pytest.mark.parametrize("task", ["InvertedPendulum", "HalfCheetah"])
def test_set_state_from_obs_round_trip(task):
    env = make_env(task)
    obs, _ = env.reset(seed=2)
    for _ in range(5):
        obs = env.step(env.action_space.sample())[0]
    other = make_env(task)
    other.reset(seed=9)
    set_state_from_obs(other, obs)
    a = np.full(env.action_space.shape, 0.3)
    assert np.allclose(env.unwrapped.step(a)[0], other.unwrapped.step(a)[0])
    with pytest.raises(ValueError):
        set_state_from_obs(other, obs[:-1])


def test_halfcheetah_leaves_no_mujoco_log_in_the_working_directory(tmp_path, monkeypatch):
    """gymnasium's HalfCheetah XML triggers a MuJoCo deprecation warning at compile; it goes to
    Python's warnings, not to a MUJOCO_LOG.TXT beside the user's files."""
    monkeypatch.chdir(tmp_path)
    with pytest.warns(RuntimeWarning, match="settotalmass"):
        env = make_env("HalfCheetah")
    env.close()
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()
