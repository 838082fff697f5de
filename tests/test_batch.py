"""Batched rollouts: lock-step episodes give bit-identical results to one episode at a time,
whatever the batch size and the worker count; the batched walk engine is the scalar one."""

import numpy as np
import pytest
import torch

from common.defaults import CONTROL_DT
from envs import SimWorld
from envs.batch import SimBatch
from experiments.runtime.batch import chunk_tasks, expected_generation_seconds, map_episodes, run_batch
from experiments.runtime.executors import ProcessExecutor, SerialExecutor
from experiments.runtime.grounding import grounding_spec
from experiments.runtime.tasks import EpisodeTask, run_episode
from sgat.models import ForwardModel, InverseModel
from sgat.transformer import ActionTransformer
from walk_engine import GaitParams, WalkEngine
from walk_engine.batch import BatchWalkEngine

SECONDS = 2.5


def _gaits(n: int, seed: int = 1, box: float = 0.4) -> list[list[float]]:
    """θ0 and gaits drawn in a wide box around it (some fall within seconds)."""
    rng = np.random.default_rng(seed)
    u0 = GaitParams().to_vector()
    return [GaitParams().to_array().tolist()] + [
        GaitParams.from_vector(u0 + rng.uniform(-box, box, len(u0)), clip=True).to_array().tolist() for _ in range(n - 1)]


def _assert_same(a: list, b: list) -> None:
    assert len(a) == len(b)
    for x, y in zip(a, b):
        rx, ry = x.recording, y.recording
        assert x.metrics() == y.metrics()  # fitness, speed, fall, fall time, drift, steps: bit for bit
        if rx is not None:
            assert ry is not None and rx[1] == ry[1] and set(rx[0]) == set(ry[0])
            for c in rx[0]:
                assert np.array_equal(rx[0][c], ry[0][c], equal_nan=True), c


@pytest.fixture(scope="module")
def transformers(tmp_path_factory):
    """Saved SGAT (2-member ensemble; one Gaussian, a 3-component mixture, a delay of 2 steps) and GAT
    transformers with random (untrained) weights: they push the legs around enough to make some walks
    fall."""
    spec = grounding_spec(SimWorld())
    S, A = spec.state_dim, spec.action_dim
    out = {}
    for name, method, K, d in (("sgat", "sgat", 1, 0), ("gat", "gat", 1, 0), ("sgat-mdn", "sgat", 3, 0),
                               ("sgat-delay", "sgat", 1, 2), ("gat-delay", "gat", 1, 2)):
        torch.manual_seed({"sgat": 7, "gat": 8}.get(name, 9))
        fw = [ForwardModel(S, A, stochastic=method == "sgat", components=K, commands=d) for _ in range(2)]
        inv = [InverseModel(S, A, commands=d) for _ in range(2)]
        path = tmp_path_factory.mktemp(name)
        ActionTransformer(spec, fw, inv, method=method, alpha=0.3, seed=0).save(path)
        out[name] = str(path)
    return out


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    """A diagnosis report with one effect of every kind the identified sim builds differently: a
    latency (delay buffers), backlash and joint compliance (series hinges), an encoder offset, a gain,
    friction, and uneven ground (a model per episode on its own random surface)."""
    import json

    path = tmp_path_factory.mktemp("report") / "report.json"
    path.write_text(json.dumps({
        "model": {"latency": 0.012, "backlash[LAnklePitch]": 0.01, "joint_compliance[RKneePitch]": 0.01,
                  "sensor_bias[LHipPitch]": 0.004, "pd_gain[RAnklePitch]": 0.9, "coulomb_friction[LKneePitch]": 0.05},
        "effects": [{"family": "terrain_roughness", "value": 0.003}]}))
    return str(path)


@pytest.mark.parametrize("world", ["sim", "ane", "sgat", "gat", "sgat-mdn", "gat-delay", "sgat-ane", "identified",
                                   "hybrid", "hybrid-delay", "terrain"])
def test_batched_episodes_are_bit_identical_to_single_episodes(world, transformers, report):
    """Every MuJoCo world the optimizer trains in, and the sim on given heightfields (stress tests):
    results and recordings equal run_episode's, falls included."""
    kw = {"sim": {"world": "sim"}, "ane": {"world": "sim", "action_noise": 0.05},
          "sgat": {"world": "sim", "transformer": transformers.get("sgat")},
          "gat": {"world": "sim", "transformer": transformers.get("gat")},
          "sgat-mdn": {"world": "sim", "transformer": transformers.get("sgat-mdn")},
          "gat-delay": {"world": "sim", "transformer": transformers.get("gat-delay")},
          "sgat-ane": {"world": "sim", "transformer": transformers.get("sgat"), "action_noise": 0.05},
          "identified": {"world": "identified", "identified": (report,)},
          "hybrid": {"world": "identified", "transformer": transformers.get("sgat"), "identified": (report,)},
          "hybrid-delay": {"world": "identified", "transformer": transformers.get("sgat-delay"), "identified": (report,)},
          "terrain": {"world": "sim"}}[world]
    tasks = [EpisodeTask(theta=th, seed=10 + i, seconds=SECONDS, record=True,
                         terrain=("lumpy", i, 0.01 * (i % 3)) if world == "terrain" else None, **kw)
             for i, th in enumerate(_gaits(6))]
    single = [run_episode(t) for t in tasks]
    batched = run_batch(tasks)
    _assert_same(single, batched)
    falls = sum(r.fell for r in single)
    assert 0 < falls < len(tasks), "the panel should hold walks that fall and walks that do not"


def test_generation_estimate_extrapolates_a_trial_batch_of_the_tasks_own_world(monkeypatch):
    """The estimate walks one batch of the generation's size in the task's own world (its keys kept,
    its seed, record and meta replaced) for two trial lengths after a warm-up, and extrapolates:
    on a clock that a batch advances by 0.05 s per episode plus 2 ms per episode and control step,
    it recovers exactly those and prices the generation from them, batch rounds included; a task that
    does not run batched (the real world) is priced as one episode at a time."""
    import types

    import experiments.runtime.batch as B

    clock = [0.0]
    calls = []

    def fake_batch(tasks):
        calls.append(tasks)
        clock[0] += sum(0.05 + 0.002 * round(t.seconds / CONTROL_DT) for t in tasks)
        return [None for _ in tasks]

    monkeypatch.setattr(B, "time", types.SimpleNamespace(perf_counter=lambda: clock[0]))
    monkeypatch.setattr(B, "run_batch", fake_batch)
    task = EpisodeTask("identified", _gaits(1)[0], 17, 7.5, transformer="models/hybrid_step1",
                       identified=("fixed.json", "floating.json"), record=True, meta={"x": 1}, key="k")
    est = expected_generation_seconds(task, episodes=12, workers=2)
    assert (est["batch"], est["rounds"]) == (6, 1)
    assert est["step_ms"] == pytest.approx(6 * 2.0) and est["batch_fixed_s"] == pytest.approx(6 * 0.05)
    assert est["expected_s"] == pytest.approx(6 * 0.05 + 750 * 6 * 0.002)
    warm, short, long = calls
    assert len(warm) == 1 and [len(short), len(long)] == [6, 6]
    assert [t.seed for t in short] == list(range(6)) and [round(t.seconds / CONTROL_DT) for t in (*short, *long)] == [10] * 6 + [110] * 6
    for t in short + long:
        assert (t.world, t.transformer, t.identified, t.theta) == (task.world, task.transformer, task.identified, task.theta)
        assert not t.record and not t.meta and not t.key
    # a paper-scale generation: 300 episodes on 2 workers are 4 batches of 75, two per worker
    calls.clear()
    big = expected_generation_seconds(task, episodes=300, workers=2)
    assert (big["batch"], big["rounds"]) == (75, 2) and len(calls[1]) == 75
    assert big["expected_s"] == pytest.approx(2 * (75 * 0.05 + 750 * 75 * 0.002))
    # the real world runs one episode at a time: 12 episodes on 2 workers are 6 rounds of one
    calls.clear()
    real = expected_generation_seconds(task.replace(world="real", identified=(), transformer=None), episodes=12, workers=2)
    assert (real["batch"], real["rounds"]) == (1, 6) and all(len(c) == 1 for c in calls)
    assert real["expected_s"] == pytest.approx(6 * (0.05 + 750 * 0.002))
    with pytest.raises(ValueError, match="episodes and workers"):
        expected_generation_seconds(task, episodes=0, workers=2)


def test_generation_estimate_walks_the_identified_ground(tmp_path):
    """Unfaked: the trial walks the identified world on its random ground (a model per episode) and
    gives a finite, positive price for a generation of 12 on 2 workers."""
    import json

    report = tmp_path / "rough.json"
    report.write_text(json.dumps({"model": {"latency": 0.012}, "effects": [{"family": "terrain_roughness", "value": 0.003}]}))
    est = expected_generation_seconds(EpisodeTask("identified", _gaits(1)[0], 0, 1.0, identified=(str(report),)),
                                      episodes=12, workers=2)
    assert (est["batch"], est["rounds"]) == (6, 1)
    assert np.isfinite(est["expected_s"]) and est["expected_s"] > 0 and est["step_ms"] > 0


def test_mixed_worlds_keep_task_order(transformers):
    """Real-world tasks run one by one, the rest in lock-step; results come back in task order."""
    th = _gaits(3)
    tasks = [EpisodeTask("sim", th[0], 1, 1.0), EpisodeTask("real", th[0], 1, 1.0),
             EpisodeTask("sim", th[1], 2, 1.0, transformer=transformers["sgat"]), EpisodeTask("sim", th[2], 3, 1.0)]
    _assert_same([run_episode(t) for t in tasks], run_batch(tasks))


def test_results_do_not_depend_on_batch_size_or_workers(transformers):
    tasks = [EpisodeTask("sim", th, 20 + i, 1.5, transformer=transformers["sgat"]) for i, th in enumerate(_gaits(7, seed=2))]
    ref = map_episodes(SerialExecutor(), tasks, batch_size=1)
    for bs in (2, 7):
        _assert_same(ref, map_episodes(SerialExecutor(), tasks, batch_size=bs))
    with ProcessExecutor(2) as ex:
        done = []
        _assert_same(ref, map_episodes(ex, tasks, progress=done.append))
    assert sum(done) == len(tasks)


def test_chunks_split_by_world_and_cover_every_task():
    th = _gaits(1)[0]
    tasks = ([EpisodeTask("sim", th, i) for i in range(10)] + [EpisodeTask("real", th, 0)]
             + [EpisodeTask("sim", th, i, transformer="a") for i in range(3)])
    chunks = chunk_tasks(tasks, workers=2, batch_size=4)
    assert sorted(i for c in chunks for i in c) == list(range(len(tasks)))
    assert [10] in chunks  # the real-world task alone
    for c in chunks:
        assert len({(tasks[i].world, tasks[i].transformer) for i in c}) == 1
        assert len(c) <= 4
    with pytest.raises(ValueError, match="batch_size"):
        chunk_tasks(tasks, batch_size=0)


def test_batch_engine_matches_scalar_engine_on_the_same_observations():
    """Fed identical (synthetic, noisy) observation streams, every row of the batched engine equals
    the scalar engine's targets, through phase changes and the start blend."""
    robot = SimWorld().robot
    params = [GaitParams.from_array(np.asarray(th)) for th in _gaits(5, seed=4, box=0.3)]
    rng = np.random.default_rng(0)
    obs = np.tile(np.zeros(62), (5, 1))
    obs[:, :24] = robot.pose("crouch") + rng.normal(0, 0.02, (5, 24))
    scalar = [WalkEngine(robot, p) for p in params]
    for e, o in zip(scalar, obs):
        e.reset(o)
    batch = BatchWalkEngine(robot, params)
    batch.reset(obs)
    idx = np.arange(5)
    for k in range(150):
        obs = obs + rng.normal(0, 0.05, obs.shape)
        if k == 100:
            idx = idx[[0, 2, 3]]  # episodes leave the batch
        got = batch.step(obs, idx)
        want = np.stack([scalar[i].step(obs[i]) for i in idx])
        assert np.array_equal(got, want), k


def test_sim_batch_rejects_bad_actions_and_other_worlds():
    env = SimWorld()
    sim = SimBatch(env, 2)
    sim.reset([0, 1])
    a = np.tile(env.robot.pose("crouch", actuated=True), (2, 1))
    a[1, 3] = np.nan
    with pytest.raises(ValueError, match="episode 1.*NaN"):
        sim.step(a)
    with pytest.raises(ValueError, match="shape"):
        sim.step(a[:1])
    with pytest.raises(TypeError, match="SimWorld"):
        from envs import RealWorld

        SimBatch(RealWorld(), 2)


def test_ground_stack_gives_each_episode_its_own_ground_bit_for_bit():
    """The batch's fall check asks every episode's ground in one call (envs.base.GroundStack): each
    height equals ground_height on that episode's own field, bit for bit, for random surfaces of one
    shape with planes among them, for fields of several shapes, and outside a field (its edge)."""
    from envs.base import GroundStack, ground_height
    from terrain import gaussian

    rng = np.random.default_rng(3)
    same = [gaussian(np.random.default_rng(s), 0.004, 0.05) for s in range(4)]
    other = gaussian(np.random.default_rng(9), 0.004, 0.05, size=(2.0, 1.0))
    for fields in (same, same[:2] + [None] + same[2:], [same[0], other, None]):
        stack = GroundStack(fields)
        assert stack.uneven
        n = 200
        ep = rng.integers(0, len(fields), n)
        x, y = rng.uniform(-3.5, 3.5, n), rng.uniform(-2.0, 2.0, n)  # some beyond the fields' edges
        got = stack.height(ep, x, y)
        want = np.array([float(ground_height(fields[e], x[j], y[j])) for j, e in enumerate(ep)])
        assert np.array_equal(got, want)
        assert np.ptp(got) > 0.005  # the surfaces are not flat: a wrong field or point would show
    assert not GroundStack([None, None]).uneven
    assert np.array_equal(GroundStack([None, None]).height([0, 1], [0.3, -2.0], [0.1, 5.0]), [0.0, 0.0])


def test_a_task_on_a_given_heightfield_leaves_the_plain_worlds_ground_alone():
    """Workers keep their worlds between tasks: a stress trial that lays a heightfield down must not
    leave it under the next plain task of the same world (one episode or a batch)."""
    th = _gaits(1)[0]
    plain = EpisodeTask("sim", th, 5, 1.5, record=True)
    before = run_episode(plain)
    bumpy = EpisodeTask("sim", th, 5, 1.5, terrain=("lumpy", 3, 0.03))
    assert run_episode(bumpy).terrain != "flat"
    _assert_same([before, before], [run_episode(plain), *run_batch([plain])])
    assert before.terrain == "flat"
