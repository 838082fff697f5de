"""SGAT grounding: models recover known maps, the transformer grounds a known mismatch."""

import gymnasium as gym
import numpy as np
import pytest
import torch

from sgat.grounding import trajectory_transitions
from sgat.models import ForwardModel, InverseModel, ModelFileError
from sgat.transformer import ActionTransformer, GroundedEnv, GroundingSpec, TeacherForcedEnv

M = np.array([[0.5, -0.2], [0.1, 0.8], [-0.3, 0.4]])
SIGMA = np.array([0.05, 0.10, 0.20])


def synthetic(n, seed, noise=True):
    rng = np.random.default_rng(seed)
    s = rng.uniform(-1, 1, (n, 3))
    a = rng.uniform(-1, 1, (n, 2))
    ds = a @ M.T + (rng.normal(0, 1, (n, 3)) * SIGMA if noise else 0.0)
    return s, a, ds


@pytest.fixture(scope="module")
def fitted():
    s, a, ds = synthetic(4000, 0)
    sgat = ForwardModel(3, 2, stochastic=True)
    sgat.fit(np.hstack([s, a]), ds, seed=0, lr=3e-3)
    gat = ForwardModel(3, 2, stochastic=False)
    gat.fit(np.hstack([s, a]), ds, seed=0, lr=3e-3)
    s2, a2, ds2 = synthetic(3000, 1, noise=False)
    inv = InverseModel(3, 2)
    inv.fit(np.hstack([s2, ds2]), a2, seed=0, lr=3e-3)
    return sgat, gat, inv


def test_forward_models_recover_mean_and_sigma(fitted):
    sgat, gat, _ = fitted
    s, a, _ = synthetic(1000, 7)
    x = np.hstack([s, a])
    true_mean = a @ M.T
    for model in (sgat, gat):
        mu, std = model.predict(x)
        rel = np.linalg.norm(mu - true_mean, axis=1).mean() / np.linalg.norm(true_mean, axis=1).mean()
        assert rel < 0.10, (model.stochastic, rel)
    _, std = sgat.predict(x)
    assert np.all(np.abs(std.mean(0) / SIGMA - 1) < 0.10), std.mean(0)
    assert np.all(gat.predict(x)[1] == 0)
    # samples spread like the real noise
    draws = sgat.sample(np.repeat(x[:1], 5000, 0), np.random.default_rng(0))
    assert np.all(np.abs(draws.std(0) / SIGMA - 1) < 0.15)


def test_inverse_model_recovers_action(fitted):
    _, _, inv = fitted
    s, a, ds = synthetic(1000, 8, noise=False)
    pred = inv.predict(np.hstack([s, ds]))
    assert np.sqrt(((pred - a) ** 2).mean()) / a.std() < 0.05


def test_save_load_weights_only(fitted, tmp_path):
    sgat, _, inv = fitted
    p = sgat.save(tmp_path / "f.pt")
    blob = torch.load(p, weights_only=True)  # plain tensors and a JSON-able config
    assert blob["config"]["kind"] == "forward"
    back = ForwardModel.load(p, expect_in=5, expect_out=3)
    x = np.random.default_rng(0).normal(size=(4, 5))
    assert np.array_equal(back.predict(x)[0], sgat.predict(x)[0])
    with pytest.raises(ModelFileError, match="3 outputs, this setting needs 7"):
        ForwardModel.load(p, expect_out=7)
    with pytest.raises(ModelFileError, match="'forward' model, expected 'inverse'"):
        InverseModel.load(p)
    (tmp_path / "bad.pt").write_bytes(b"\x00garbage")
    with pytest.raises(ModelFileError, match="not a readable"):
        ForwardModel.load(tmp_path / "bad.pt")
    with pytest.raises(FileNotFoundError):
        ForwardModel.load(tmp_path / "missing.pt")
    # a state dict of the wrong shape under a matching config
    small = ForwardModel(3, 2, hidden=(8, 8))
    blob = {"config": sgat.config(), "state_dict": small.state_dict()}
    torch.save(blob, tmp_path / "shape.pt")
    with pytest.raises(ModelFileError, match="do not match"):
        ForwardModel.load(tmp_path / "shape.pt")


def test_fit_rejects_bad_data():
    m = ForwardModel(3, 2)
    with pytest.raises(ValueError, match="expected X"):
        m.fit(np.zeros((20, 4)), np.zeros((20, 3)))
    X = np.zeros((20, 5))
    X[3, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        m.fit(X, np.zeros((20, 3)))


def _spec(S=3, A=2, k=1):
    return GroundingSpec(np.arange(S), np.arange(A), -np.ones(A), np.ones(A), k)


def test_transformer_identity_sampling_clip_blend(fitted):
    sgat, gat, inv = fitted
    spec = _spec()
    ident = ActionTransformer(spec)
    a = np.array([0.3, -0.2])
    assert ident.is_identity and np.array_equal(ident.transform(np.zeros(3), a), a)
    t = ActionTransformer(spec, sgat, inv, method="sgat", alpha=1.0, seed=3)
    t.reset(5)
    x1 = [t.transform(np.zeros(3), a) for _ in range(3)]
    t.reset(5)
    x2 = [t.transform(np.zeros(3), a) for _ in range(3)]
    assert np.array_equal(x1, x2) and not np.array_equal(x1[0], x1[1])  # seeded, stochastic
    g = ActionTransformer(spec, gat, inv, method="gat", alpha=1.0)
    assert np.array_equal(g.transform(np.zeros(3), a), g.transform(np.zeros(3), a))  # deterministic
    # this map has no sim/real gap, so GAT grounding is close to the identity
    assert np.abs(g.transform(np.zeros(3), a) - a).max() < 0.1
    assert np.all(np.abs(g.transform(np.zeros(3), np.array([5.0, -5.0]))) <= 1.0)  # clipped
    half = ActionTransformer(spec, gat, inv, method="gat", alpha=0.5)
    assert np.allclose(half.transform(np.zeros(3), a), 0.5 * a + 0.5 * g.transform(np.zeros(3), a))
    with pytest.raises(ValueError, match="unknown grounding method"):
        ActionTransformer(spec, method="magic")
    with pytest.raises(ValueError, match="alpha"):
        ActionTransformer(spec, alpha=2.0)
    with pytest.raises(ValueError, match="do not match"):
        ActionTransformer(_spec(S=4), sgat, inv, alpha=1.0)


def test_transformer_save_load(fitted, tmp_path):
    sgat, _, inv = fitted
    t = ActionTransformer(_spec(), sgat, inv, method="sgat", alpha=0.9, seed=2)
    t.save(tmp_path / "tr")
    back = ActionTransformer.load(tmp_path / "tr")
    t.reset(1)
    back.reset(1)
    assert np.array_equal(t.transform(np.ones(3), np.zeros(2)), back.transform(np.ones(3), np.zeros(2)))
    assert back.alpha == 0.9 and back.method == "sgat"


def test_history_stacking():
    spec = _spec(S=2, A=1, k=3)
    S = np.arange(10.0).reshape(5, 2)
    H = spec.stack_history(S)
    assert H.shape == (5, 6)
    assert np.array_equal(H[0], [0, 1, 0, 1, 0, 1]) and np.array_equal(H[4], [4, 5, 6, 7, 8, 9])
    tr = trajectory_transitions(np.hstack([S, np.zeros((5, 1))]), np.ones((5, 1)), spec)
    assert tr.H.shape == (4, 6) and np.array_equal(tr.dS, np.full((4, 2), 2.0))


def test_ensemble_draws_a_member_per_episode(fitted, tmp_path):
    sgat, gat, inv = fitted
    sgat2 = ForwardModel(3, 2, stochastic=True)
    s, a, ds = synthetic(2000, 5)
    sgat2.fit(np.hstack([s, a]), ds + 0.5, seed=1, lr=3e-3)  # a second member that disagrees (offset)
    ens = ActionTransformer(_spec(), [sgat, sgat2], [inv, inv], method="sgat", alpha=1.0, seed=0)
    members = set()
    for ep in range(20):
        ens.reset(ep)
        members.add(ens.member)
        first = ens.member
        ens.transform(np.zeros(3), np.zeros(2))
        assert ens.member == first  # kept for the whole episode
    assert members == {0, 1}
    ens.reset(4)
    m4 = ens.member
    ens.reset(4)
    assert ens.member == m4  # the episode seed decides
    ens.save(tmp_path / "ens")
    back = ActionTransformer.load(tmp_path / "ens")
    assert back.n_members == 2 and (tmp_path / "ens" / "forward_1.pt").exists()
    back.reset(7)
    ens.reset(7)
    assert np.array_equal(back.transform(np.ones(3), np.zeros(2)), ens.transform(np.ones(3), np.zeros(2)))
    g = ActionTransformer(_spec(), [gat, gat], [inv, inv], method="gat", alpha=1.0)
    one = ActionTransformer(_spec(), gat, inv, method="gat", alpha=1.0)
    assert np.allclose(g.transform(np.zeros(3), np.ones(2) * 0.2), one.transform(np.zeros(3), np.ones(2) * 0.2))
    with pytest.raises(ValueError, match="equal numbers"):
        ActionTransformer(_spec(), [sgat, sgat2], [inv], alpha=1.0)
    with pytest.raises(ValueError, match="alpha"):
        ActionTransformer(_spec(), sgat, inv)


def test_gat_transformer_recovers_a_known_action_gain(fitted):
    """A real world whose actuators deliver 0.7× and 1.3× of the command (ds = (g ⊙ a) Mᵀ) and a sim
    that delivers 1× (ds = a Mᵀ): the grounded action ã = f_sim⁻¹(s, f_real(s, a)) must be g ⊙ a
    (paper eq. 2 with α = 1), and α = 0.5 goes half way."""
    _, _, inv = fitted  # the sim's inverse model
    g = np.array([0.7, 1.3])
    rng = np.random.default_rng(11)
    s = rng.normal(0, 1, (4000, 3))
    a = rng.uniform(-0.7, 0.7, (4000, 2))
    real = ForwardModel(3, 2, stochastic=False)
    real.fit(np.hstack([s, a]), (a * g) @ M.T, seed=0, lr=3e-3)
    t = ActionTransformer(_spec(), real, inv, method="gat", alpha=1.0)
    half = ActionTransformer(_spec(), real, inv, method="gat", alpha=0.5)
    for k in range(20):
        ak = rng.uniform(-0.7, 0.7, 2)
        sk = rng.normal(0, 1, 3)
        assert np.abs(t.transform(sk, ak) - g * ak).max() < 0.06, (ak, t.transform(sk, ak))
        assert np.abs(half.transform(sk, ak) - (1 + g) / 2 * ak).max() < 0.04


def _bumpy(n, seed):
    """Δs = a M^T + small noise, except that with probability 0.2 (a swing foot catching a bump) the
    first state dimension jumps by -0.6 more: a two-mode transition one Gaussian cannot hold."""
    rng = np.random.default_rng(seed)
    s, a = rng.uniform(-1, 1, (n, 3)), rng.uniform(-1, 1, (n, 2))
    bump = rng.random(n) < 0.2
    ds = a @ M.T + rng.normal(0, 0.03, (n, 3))
    ds[bump, 0] -= 0.6
    return np.hstack([s, a]), ds, bump


def test_mixture_forward_model_recovers_a_two_mode_transition(tmp_path):
    """A mixture density forward model (components=2) finds the rare mode (weight ~0.2, offset
    -0.6) that one Gaussian smears into a wide symmetric spread, beats it on held-out likelihood,
    samples both modes at their rates, and survives save/load."""
    X, Y, _ = _bumpy(6000, 0)
    one = ForwardModel(3, 2, stochastic=True)
    one.fit(X, Y, seed=0, lr=3e-3)
    mdn = ForwardModel(3, 2, stochastic=True, components=2)
    mdn.fit(X, Y, seed=0, lr=3e-3)
    Xt, Yt, _ = _bumpy(2000, 1)

    def nll(m):
        w, mu, sd = m.mixture(Xt)
        lp = (-0.5 * ((Yt[:, None] - mu) / sd) ** 2 - np.log(sd) - 0.5 * np.log(2 * np.pi)).sum(-1)
        return -np.log((w * np.exp(lp)).sum(-1)).mean()

    assert nll(mdn) < nll(one) - 0.5, (nll(mdn), nll(one))
    w, mu, sd = mdn.mixture(Xt)
    rare = np.argmin(w.mean(0))
    assert abs(w[:, rare].mean() - 0.2) < 0.05
    offset = (mu[:, rare, 0] - mu[:, 1 - rare, 0]).mean()
    assert abs(offset + 0.6) < 0.06, offset
    # the mixture's moments: the mean is the weighted mean, the spread includes the gap between modes
    m, s = mdn.predict(Xt)
    assert np.allclose(m, np.einsum("nk,nks->ns", w, mu))
    assert s[:, 0].mean() > 0.2 and s[:, 1].mean() < 0.1
    # samples of one input: about 20 % in the rare mode
    x = np.repeat(Xt[:1], 20000, 0)
    d = mdn.sample(x, np.random.default_rng(3))[:, 0]
    lo = (d < (mu[0, 0, 0] + mu[0, 1, 0]) / 2).mean()
    assert abs(lo - w[0, rare]) < 0.02, (lo, w[0, rare])
    # one Gaussian cannot: its samples are symmetric about the mean
    d1 = one.sample(x, np.random.default_rng(3))[:, 0]
    assert abs(np.median(d1) - d1.mean()) < 0.03
    path = tmp_path / "mdn.pt"
    mdn.save(path)
    back = ForwardModel.load(path, expect_in=5, expect_out=3)
    assert back.components == 2
    assert np.array_equal(back.sample_with(Xt[:5], np.ones((5, 4))), mdn.sample_with(Xt[:5], np.ones((5, 4))))


def test_mixture_forward_model_rejects_bad_settings():
    with pytest.raises(ValueError, match="components"):
        ForwardModel(3, 2, stochastic=False, components=2)
    with pytest.raises(ValueError, match="components"):
        ForwardModel(3, 2, components=0)


def test_linear_models_recover_a_linear_map(tmp_path):
    """hidden=(): the forward model is linear in (s, a) (mean and log σ), the inverse model linear in
    (s, Δs); on a linear system both recover the map, and they save and load."""
    s, a, ds = synthetic(4000, 0)
    fwd = ForwardModel(3, 2, stochastic=True, hidden=())
    fwd.fit(np.hstack([s, a]), ds, seed=0, lr=3e-3)
    s2, a2, _ = synthetic(500, 5)
    mu, std = fwd.predict(np.hstack([s2, a2]))
    assert np.abs(mu - a2 @ M.T).max() < 0.05
    assert np.all(np.abs(std.mean(0) / SIGMA - 1) < 0.1)
    s3, a3, ds3 = synthetic(3000, 1, noise=False)
    inv = InverseModel(3, 2, hidden=())
    inv.fit(np.hstack([s3, ds3]), a3, seed=0, lr=3e-3)
    s4, a4, ds4 = synthetic(500, 6, noise=False)
    assert np.sqrt(((inv.predict(np.hstack([s4, ds4])) - a4) ** 2).mean()) < 0.02
    fwd.save(tmp_path / "f.pt")
    back = ForwardModel.load(tmp_path / "f.pt")
    assert back.hidden == () and np.array_equal(back.predict(np.hstack([s2, a2]))[0], mu)


def test_delay_lets_the_transformer_ground_a_sim_that_answers_late():
    """A real world and a sim that both execute every command two steps late (s_{t+1} = s_t +
    a_{t-2} Mᵀ), the sim with other gains (M diag(g)): a_t shows in neither before s_{t+3}. With
    ``delay=2`` the grounded action is a / g given the actions already sent (â_{t-2}, â_{t-1} = their
    commands / g), exactly the sim command that lands where the real one does; the paper's one-step
    models cannot see a_t in either world and do not."""
    from sgat.grounding import GroundingConfig, Transitions, fit_grounding

    rng = np.random.default_rng(23)
    spec = _spec()
    g = np.array([0.5, 2.0])

    def walk(n, gain):
        s = np.zeros((n, 3))
        a = rng.uniform(-0.7, 0.7, (n, 2))
        for t in range(n - 1):
            s[t + 1] = s[t] + (a[max(t - 2, 0)] * gain) @ M.T
        return s, a

    def rows(gain, **kw):
        return Transitions.concat([trajectory_transitions(*walk(600, gain), spec, **kw) for _ in range(4)])

    real, sim = rows(np.ones(2), past=2, delay=2), rows(g, past=2, delay=2)
    assert real.past_commands == 2 and len(real) == 4 * (600 - 3)  # rows bridge three steps
    cfg = GroundingConfig(alpha=1.0, method="gat", hidden=(), delay=2, max_epochs=300)
    tr = fit_grounding(real, sim, spec, cfg).transformer
    one_step = fit_grounding(rows(np.ones(2)), rows(g), spec,
                             GroundingConfig(alpha=1.0, method="gat", hidden=(), max_epochs=300)).transformer
    assert tr.delay == 2 and tr.commands == 2 and one_step.delay == 0
    err, err1 = [], []
    for _ in range(30):
        past, a, s = rng.uniform(-0.35, 0.35, 4), rng.uniform(-0.35, 0.35, 2), rng.normal(0, 1, 3)  # a / g inside ±1
        err.append(np.abs(tr.transform(s, a, past, sent=past / np.tile(g, 2)) - a / g).max())
        err1.append(np.abs(one_step.transform(s, a) - a / g).max())
    assert max(err) < 0.06, max(err)
    assert np.median(err1) > 0.2
    with pytest.raises(ValueError, match="sent"):
        tr.transform(s, a, past)
    with pytest.raises(ValueError, match="delay must be >= 0"):
        GroundingConfig(alpha=0.5, delay=-1)
    with pytest.raises(ValueError, match="past"):  # the sim rows must hold the actions sent before
        fit_grounding(real, rows(g, delay=2), spec, cfg)


def _gait(n, seed, P, gain=(1.0, 1.0), explore=0.05, process=0.05):
    """Walk-like transitions: the commands follow a policy of the state, a = P s + exploration noise
    (a gait commands what its phase asks for), Δs = (gain ⊙ a) Mᵀ + process noise."""
    from sgat.grounding import Transitions

    rng = np.random.default_rng(seed)
    s = rng.uniform(-1, 1, (n, 3))
    a = s @ P.T + rng.normal(0, explore, (n, 2))
    return Transitions(s, a, (a * np.asarray(gain)) @ M.T + rng.normal(0, process, (n, 3)))


def _servo_walk(n, seed, P, gain=(1.0, 1.0), explore=0.05, process=0.05):
    """Two position-servoed joints: Δq = K (gain ⊙ a − q) + process noise, commands from a gait's
    policy of the whole state, a = P q + exploration noise (each joint's command follows the *other*
    joint's angle, as a gait's phase couples the legs)."""
    from sgat.grounding import Transitions

    rng = np.random.default_rng(seed)
    q = rng.uniform(-1, 1, (n, 2))
    a = q @ P.T + rng.normal(0, explore, (n, 2))
    return Transitions(q, a, (np.asarray(gain) * a - q) * np.array([0.5, 0.8]) + rng.normal(0, process, (n, 2)))


class _Still(gym.Env):
    """A world whose state never moves, whatever the action: the sim never follows a target."""

    observation_space = gym.spaces.Box(-10, 10, (3,))
    action_space = gym.spaces.Box(-1, 1, (2,))

    def reset(self, *, seed=None, options=None):
        return np.zeros(3), {}

    def step(self, action):
        return np.zeros(3), 0.0, False, False, {}


def test_teacher_forcing_asks_the_inverse_model_for_the_recorded_next_states(fitted):
    """TeacherForcedEnv: at step t the target is the recording's s_{t+1}, asked of the inverse model
    from the sim's own state; after the recording ends the commands pass through ungrounded."""
    sgat, gat, inv = fitted
    spec, a = _spec(), np.array([0.3, -0.2])
    ref = np.random.default_rng(0).uniform(-0.3, 0.3, (5, 3))
    tr = ActionTransformer(spec, gat, inv, method="gat", alpha=0.5)
    env = TeacherForcedEnv(_Still(), tr, ref)
    env.reset(seed=0)
    got = np.array([env.step(a)[4]["applied_action"] for _ in range(7)])
    for t in range(4):
        assert np.allclose(got[t], 0.5 * a + 0.5 * inv.predict(np.concatenate([np.zeros(3), ref[t + 1]])), atol=1e-12)
    assert np.array_equal(got[4:], np.tile(a, (3, 1)))  # the sim's own dynamics from step T-1
    with pytest.raises(ValueError, match="fitted transformer"):
        TeacherForcedEnv(_Still(), ActionTransformer(spec), ref)
    with pytest.raises(ValueError, match="reference"):
        TeacherForcedEnv(_Still(), tr, ref[:, :2])
    with pytest.raises(ValueError, match="reference"):
        TeacherForcedEnv(_Still(), tr, np.full((4, 3), np.nan))


def test_ensemble_members_fitted_on_a_process_pool_equal_the_serial_fit():
    """fit_grounding's map_fn (optimize passes its executor's map): an ensemble whose members are
    fitted side by side in worker processes is the serial fit, every weight bit for bit; the members
    differ from one another (bootstrap resamples, seeds)."""
    from experiments.runtime.executors import ProcessExecutor
    from sgat.grounding import GroundingConfig, fit_grounding

    spec = _spec()
    P = np.array([[0.6, -0.3, 0.2], [-0.2, 0.5, 0.4]])
    real, sim = _gait(600, 3, P, gain=[0.7, 1.3], explore=0.2), _gait(600, 1, P, explore=0.2)
    cfg = GroundingConfig(alpha=0.5, method="sgat", hidden=(8,), ensemble=3, max_epochs=20)

    def weights(tr):
        models = list(tr.forwards) + list(tr.inverses)
        return [p.detach().clone() for m in models for p in m.state_dict().values()]

    serial = fit_grounding(real, sim, spec, cfg, seed=4)
    with ProcessExecutor(2) as ex:
        pooled = fit_grounding(real, sim, spec, cfg, seed=4, map_fn=ex.map)
    wa, wb = weights(serial.transformer), weights(pooled.transformer)
    assert len(wa) == len(wb) and all(torch.equal(x, y) for x, y in zip(wa, wb))
    assert [r.val_loss for r in serial.forward_reports] == [r.val_loss for r in pooled.forward_reports]
    f = serial.transformer.forwards
    assert not torch.equal(f[0].net.body[0].weight, f[1].net.body[0].weight)
    assert serial.transformer.n_members == 3


class _Walk:
    """The parts of an ``envs.Recording`` that ``command_visibility`` reads: observation columns and
    the applied and commanded action groups."""

    def __init__(self, q: np.ndarray, applied: np.ndarray, commanded: np.ndarray):
        self.columns = {f"q{j}": q[:, j] for j in range(q.shape[1])}
        self._groups = {"app": applied, "cmd": commanded}

    def group(self, name: str) -> np.ndarray:
        return self._groups[name]


def _delayed_servo_walks(delay: int, n: int = 6, steps: int = 400, seed: int = 0) -> list:
    """Walks of three first-order servos q_{t+1} = 0.7 q_t + 0.3 u_{t-delay}, commanded a periodic
    pattern with white exploration noise (σ 0.02) on the applied targets u."""
    rng = np.random.default_rng(seed)
    walks = []
    for _ in range(n):
        t = np.arange(steps)
        c = 0.3 * np.sin(2 * np.pi * t[:, None] / 50 + np.array([0.0, 1.0, 2.0]))
        u = c + 0.02 * rng.standard_normal(c.shape)
        q = np.zeros_like(c)
        for k in range(steps - 1):
            q[k + 1] = 0.7 * q[k] + 0.3 * u[max(k - delay, 0)]
        walks.append(_Walk(q, u, c))
    return walks


@pytest.mark.parametrize("delay", [0, 2])
def test_command_visibility_finds_the_lead_at_which_a_delayed_command_shows(delay):
    from types import SimpleNamespace

    from sgat.grounding import command_visibility

    spec = GroundingSpec(np.arange(3), np.arange(3), -np.ones(3), np.ones(3), history=2)
    layout = SimpleNamespace(names=["q0", "q1", "q2"])
    res = command_visibility(_delayed_servo_walks(delay), layout, spec, leads=(1, 2, 3, 4))
    r2 = dict(zip(res["leads"], res["r2"]))
    assert res["best_lead"] == delay + 1
    # the noise on u_t shows in q_{t+delay+1} (beside that of the commands still in the pipeline)
    assert r2[delay + 1] > 0.25
    for k in range(1, delay + 1):  # ... and not at all before
        assert r2[k] < 0.05
    assert res["noise_rad"] == pytest.approx(0.02, rel=0.1)


def test_command_visibility_rejects_unusable_walks():
    from types import SimpleNamespace

    from sgat.grounding import command_visibility

    spec = GroundingSpec(np.arange(3), np.arange(3), -np.ones(3), np.ones(3), history=2)
    layout = SimpleNamespace(names=["q0", "q1", "q2"])
    walks = _delayed_servo_walks(0, n=3)
    with pytest.raises(ValueError, match="at least 2 walks"):
        command_visibility(walks[:1], layout, spec)
    with pytest.raises(ValueError, match="leads >= 1"):
        command_visibility(walks, layout, spec, leads=(0, 1))
    quiet = [_Walk(np.asarray([w.columns[n] for n in layout.names]).T, w.group("cmd"), w.group("cmd")) for w in walks]
    with pytest.raises(ValueError, match="no exploration noise"):
        command_visibility(quiet, layout, spec)
    short = [_Walk(np.zeros((3, 3)), w.group("app")[:3], w.group("cmd")[:3]) for w in walks]
    with pytest.raises(ValueError, match="too short"):
        command_visibility(short, layout, spec, leads=(1, 4))
