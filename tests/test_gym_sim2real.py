"""The gym sim-to-real pipeline: policies in NumPy, grounding InvertedPendulum, results table,
summary/figure, CLI. The end-to-end sweep is a slow test."""

import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

from experiments.gym import run as G
from experiments.gym.config import GymConfig
from experiments.gym.envs import make_env

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture(autouse=True, scope="module")
def _one_thread():
    import torch

    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


def _untrained_blob(task="InvertedPendulum", normalize=False):
    from sb3_contrib import TRPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    venv = DummyVecEnv([lambda: make_env(task)])
    if normalize:
        venv = VecNormalize(venv)
        venv.obs_rms.mean = np.linspace(-1, 1, venv.observation_space.shape[0])
        venv.obs_rms.var = np.linspace(0.5, 2, venv.observation_space.shape[0])
    model = TRPO("MlpPolicy", venv, seed=4, device="cpu")
    with_log_std = model.policy.log_std.data
    with_log_std[:] = -0.5
    return model, venv, G._policy_blob(model, venv)


@pytest.mark.parametrize("task,normalize", [("InvertedPendulum", False), ("HalfCheetah", True)])
def test_numpy_policy_matches_sb3_predict(tmp_path, task, normalize):
    model, venv, blob = _untrained_blob(task, normalize)
    path = G.save_policy(blob, tmp_path / "p.npz")
    pol = G.NumpyPolicy(G.load_policy(path))
    obs = np.random.default_rng(0).normal(size=(64, venv.observation_space.shape[0]))
    want = model.predict(venv.normalize_obs(obs) if normalize else obs, deterministic=True)[0]
    assert np.allclose(pol.act(obs), want, atol=1e-5)
    assert np.allclose(pol.std, np.exp(-0.5))
    a = pol.act(obs[0], deterministic=False, rng=np.random.default_rng(1))
    assert np.all(a >= pol.low) and np.all(a <= pol.high)
    with pytest.raises(ValueError):
        pol.act(obs[0], deterministic=False)


def test_training_leaves_no_logger_folder(tmp_path, monkeypatch):
    """SB3's default logger makes an empty SB3-<date> folder in the temp directory on every training;
    train_policy gives the model one that writes nothing."""
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    cfg = GymConfig.from_preset("InvertedPendulum", "quick")
    blob = G.train_policy(cfg, lambda i: make_env("InvertedPendulum"), 256, seed=0)
    assert G.NumpyPolicy(blob).act(np.zeros(4)).shape == (1,)
    assert not list(tmp_path.glob("SB3-*"))


def test_policy_file_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        G.load_policy(tmp_path / "missing.npz")
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="not a readable policy file"):
        G.load_policy(bad)


class _PD:
    """A stabilising linear controller for the InvertedPendulum (duck-types NumpyPolicy)."""

    low, high, std = np.array([-3.0]), np.array([3.0]), np.array([0.5])

    def act(self, obs, deterministic=True, rng=None):
        x, th, dx, dth = obs
        a = np.array([0.5 * x + 8.0 * th + 0.4 * dx + 1.0 * dth])
        if not deterministic:
            a = a + self.std * rng.standard_normal(1)
        return np.clip(a, self.low, self.high)


def test_grounded_pendulum_predicts_the_heavy_real_pendulum_better():
    """GroundedEnv on InvertedPendulum with a learned (GAT) transformer: smaller one-step
    next-state error against the 10x-heavier real pendulum than the plain sim (small scale)."""
    from sgat.grounding import fit_transformer
    from sgat.transformer import GroundedEnv, GroundingSpec

    pd = _PD()
    real = make_env("InvertedPendulum", heavy=True)
    sim = make_env("InvertedPendulum")
    spec = GroundingSpec.full(sim)
    real_eps = G.collect(real, pd, 1500, seed=1)
    sim_eps = G.collect(sim, pd, 3000, seed=2, explore=0.3)
    fit = fit_transformer(G.episodes_to_transitions(real_eps, spec), G.episodes_to_transitions(sim_eps, spec), spec,
                          method="gat", alpha=1.0, seed=0, fit_kwargs={"max_epochs": 40, "batch_size": 256, "lr": 3e-3})
    # (a) states along held-out real trajectories (GARAT's per-step transition error)
    held = G.collect(real, pd, 400, seed=3)
    err = G.one_step_errors("InvertedPendulum", fit.transformer, held)
    assert err["grounded"] < 0.25 * err["sim"], err
    # (b) the GroundedEnv wrapper itself, from the same reset states as real
    grounded = GroundedEnv(make_env("InvertedPendulum"), fit.transformer)
    e_plain, e_grounded = [], []
    rng = np.random.default_rng(5)
    for k in range(20):
        o_r, _ = real.reset(seed=100 + k)
        o_g, _ = grounded.reset(seed=100 + k)
        o_s, _ = sim.reset(seed=100 + k)
        assert np.allclose(o_r, o_g) and np.allclose(o_r, o_s)
        a = pd.act(o_r, False, rng)
        n_r = real.step(a)[0]
        n_g, _, _, _, info = grounded.step(a)
        n_s = sim.step(a)[0]
        assert np.array_equal(info["commanded_action"], a)
        e_plain.append(np.linalg.norm(n_s - n_r))
        e_grounded.append(np.linalg.norm(n_g - n_r))
    assert np.mean(e_grounded) < 0.5 * np.mean(e_plain), (np.mean(e_grounded), np.mean(e_plain))


def _rows(cfg, fp=None):
    rows = []
    for nz, base in ((0.0, 900.0), (0.3, 400.0)):
        for r in range(3):
            for m, f in (("sim", 0.2), ("gat", 0.6), ("sgat", 0.8), ("real", 1.0)):
                rows.append({"env": cfg.env, "experiment": cfg.experiment, "noise": nz, "method": m, "run": r,
                             "return_mean": base * f + r, "fingerprint": fp or G.fingerprint_hash(cfg, m),
                             "wall_s": 1.0})
            for s, f in ((0.1, 0.5), (0.3, 0.7 if nz > 0 else 0.3)):
                rows.append({"env": cfg.env, "experiment": cfg.experiment, "noise": nz, "method": "ane", "run": r,
                             "ane_sigma": s, "return_mean": base * f, "fingerprint": fp or G.fingerprint_hash(cfg, "ane"),
                             "wall_s": 1.0})
    return [G._normalize_row(r) for r in rows]


def test_summary_normalizes_to_real_and_selects_ane_sigma(tmp_path):
    cfg = GymConfig.from_preset("InvertedPendulum", "quick", runs=3)
    summary = G.summarize(_rows(cfg), cfg)
    get = {(s["noise"], s["method"]): s for s in summary}
    assert get[(0.0, "real")]["normalized"] == pytest.approx(1.0)
    assert get[(0.3, "sgat")]["normalized"] == pytest.approx((0.8 * 400 + 1) / (400 + 1))
    assert get[(0.0, "gat")]["return_se"] == pytest.approx(np.std([540, 541, 542], ddof=1) / math.sqrt(3))
    assert get[(0.0, "ane")]["ane_sigma"] == 0.1 and get[(0.3, "ane")]["ane_sigma"] == 0.3
    assert get[(0.3, "ane")]["runs"] == 3 and get[(0.3, "ane")]["privileged"]
    assert not get[(0.3, "sim")]["uses_real_data"] and get[(0.3, "gat")]["uses_real_data"]
    text = G.format_table(summary, cfg)
    assert "SIM-ONLY" in text and "ANE σ (best on real, privileged)" in text
    png = tmp_path / "f.png"
    G.plot_bars(summary, cfg, png)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_paired_differences_pair_methods_by_run_with_a_t_interval():
    cfg = GymConfig.from_preset("InvertedPendulum", "quick", runs=3)
    rows = _rows(cfg)
    get = {(p["noise"], p["a"], p["b"]): p for p in G.paired_differences(rows, cfg)}
    same = get[(0.0, "sgat", "gat")]  # every run 180 apart: no spread to test with
    assert same["runs"] == 3 and same["mean_diff"] == pytest.approx(180) and same["p_value"] is None
    assert same["ci"] == [pytest.approx(180), pytest.approx(180)]
    assert get[(0.3, "sgat", "sim")]["mean_diff"] == pytest.approx(400 * 0.6)
    # run 0's SGAT 60 lower at noise 0: differences 120, 180, 180 -> mean 160, s.e. 20, t(2) = 4.303
    moved = [dict(r, return_mean=r["return_mean"] - 60) if (r["method"], r["run"], r["noise"]) == ("sgat", 0, 0.0)
             else r for r in rows]
    q = next(p for p in G.paired_differences(moved, cfg) if (p["noise"], p["b"]) == (0.0, "gat"))
    assert q["mean_diff"] == pytest.approx(160) and q["ci"][0] == pytest.approx(160 - 4.3027 * 20, rel=1e-4)
    assert q["p_value"] == pytest.approx(0.0153, abs=5e-4)
    # a run without one of the two methods is no pair
    short = [r for r in moved if not (r["method"] == "gat" and r["run"] == 2)]
    assert next(p for p in G.paired_differences(short, cfg) if (p["noise"], p["b"]) == (0.0, "gat"))["runs"] == 2
    text = G.format_table(G.summarize(moved, cfg), cfg, G.paired_differences(moved, cfg))
    assert "SGAT - GAT real return, paired by run" in text and "noise 0: +160 [+74, +246] p=0.015" in text


def test_result_table_resumes_and_keeps_settings_apart(tmp_path):
    cfg = GymConfig.from_preset("InvertedPendulum", "quick", runs=2)
    table = G.ResultTable(tmp_path)
    plan = G.plan_tasks(cfg, table)
    kinds = sorted(t["kind"] for t in plan["second"])
    # 2 runs: real x2 noises, sim (both noises in one job), gat/sgat x2 noises, ane x2 sigmas
    assert kinds.count("real") == 4 and kinds.count("sim") == 2 and kinds.count("gat") == 4
    assert kinds.count("ane") == 4 and plan["sim_runs"] == [0, 1]
    assert plan["second"][0]["kind"] == "real"  # longest first
    rows = [r for r in _rows(cfg) if r["run"] < 2]
    # a worker's cell file (an interrupted sweep) is merged on the next start
    G.write_rows(tmp_path / "cells" / "x.parquet", rows[:5])
    table = G.ResultTable(tmp_path)
    assert len(table.rows) == 5 and not list((tmp_path / "cells").glob("*.parquet"))
    assert table.append(rows) == len(rows) - 5
    assert table.append(rows) == 0  # duplicates ignored
    table = G.ResultTable(tmp_path)
    assert len(table.rows) == len(rows)
    plan = G.plan_tasks(cfg, table)
    assert plan == {"sim_runs": [], "second": []}
    # one missing cell -> exactly that job, and its run's sim policy
    table.rows = [r for r in table.rows if not (r["method"] == "sgat" and r["run"] == 1 and r["noise"] == 0.3)]
    table._keys = {G.row_key(r) for r in table.rows}
    plan = G.plan_tasks(cfg, table)
    assert plan["sim_runs"] == [1] and [(t["kind"], t["noise"]) for t in plan["second"]] == [("sgat", 0.3)]
    # another budget -> other fingerprints -> only the methods that depend on it re-run
    cfg2 = GymConfig.from_preset("InvertedPendulum", "quick", runs=2, sim_steps=12345)
    assert G.fingerprint_hash(cfg2, "gat") != G.fingerprint_hash(cfg, "gat")
    assert G.fingerprint_hash(cfg2, "real") == G.fingerprint_hash(cfg, "real")
    assert sorted({t["kind"] for t in G.plan_tasks(cfg2, table)["second"]}) == ["ane", "gat", "sgat", "sim"]
    cfg3 = GymConfig.from_preset("InvertedPendulum", "quick", runs=2, real_steps=99999)
    assert [t["kind"] for t in G.plan_tasks(cfg3, table)["second"]] == ["real"] * 4 + ["sgat"]  # + the removed one
    cfg4 = GymConfig.from_preset("InvertedPendulum", "quick", runs=2, pole_factor=20)
    assert len(G.plan_tasks(cfg4, table)["second"]) == 18
    assert len(table.current(cfg)) == len(rows) - 1 and table.current(cfg4) == []
    # a summary of fewer runs leaves out the rows of the runs beyond them
    cfg1 = GymConfig.from_preset("InvertedPendulum", "quick", runs=1)
    assert table.current(cfg1) and {r["run"] for r in table.current(cfg1)} == {0}


def test_config_validation():
    with pytest.raises(ValueError, match="unknown method"):
        GymConfig.from_preset("InvertedPendulum", "quick", methods=("gat", "rgat"))
    with pytest.raises(ValueError, match="unknown --preset"):
        GymConfig.from_preset("InvertedPendulum", "huge")
    with pytest.raises(ValueError, match="positive"):
        GymConfig.from_preset("HalfCheetah", "quick", runs=0)
    cfg = GymConfig.from_preset("halfcheetah-v5", "paper")
    assert cfg.env == "HalfCheetah" and cfg.grounding_steps == 5 and cfg.runs == 10
    hp = cfg.trpo_params()
    assert hp["target_kl"] == 0.04 and hp["normalize"] and hp["n_envs"] == 2 and hp["n_steps"] == 1024
    assert GymConfig.from_preset("ip", "quick").pole_factor == 10.0


def _cli(*args, cwd=ROOT):
    env = {**os.environ, "PYTHONPATH": ROOT, "OMP_NUM_THREADS": "1"}
    return subprocess.run([sys.executable, "-m", "experiments.cli", "gym", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=1800)


def test_cli_rejects_bad_input(tmp_path, capsys):
    from experiments.cli import main

    for args, msg in ((["--methods", "gat,foo"], "unknown method"), (["--noise", "0,abc"], "not a number"),
                      (["--env", "Hopper"], "unknown --env"), (["--runs", "0"], "--runs"),
                      (["--noise", "0,0"], "twice"), (["--report", "--out", str(tmp_path)], "no results table")):
        assert main(["gym", *args]) == 2, args
        err = capsys.readouterr().err
        assert msg in err and err.count("\n") == 1, err


@pytest.mark.slow
def test_cli_end_to_end_tiny_sweep_and_resume(tmp_path):
    out = tmp_path / "sweep"
    args = ["--runs", "1", "--noise", "0,0.3", "--sim-steps", "2048", "--grounded-steps", "2048", "--real-steps",
            "2048", "--real-transitions", "300", "--sim-transitions", "300", "--eval-episodes", "2",
            "--model-epochs", "3", "--workers", "2", "--out", str(out), "--json"]
    p = _cli(*args)
    assert p.returncode == 0, p.stderr
    res = json.loads(p.stdout)
    methods = {(s["noise"], s["method"]) for s in res["summary"]}
    assert methods == {(n, m) for n in (0.0, 0.3) for m in ("sim", "gat", "sgat", "ane", "real")}
    assert os.path.exists(res["files"]["figure"]) and (out / "results.parquet").exists()
    assert len(G.read_rows(out / "results.parquet")) == 12  # 2 noises x (sim, gat, sgat, real) + ane 2 σ x 2
    p = _cli(*args)
    res2 = json.loads(p.stdout)
    assert res2["tasks"] == 0 and res2["new_rows"] == 0
    assert [s["return_mean"] for s in res2["summary"]] == [s["return_mean"] for s in res["summary"]]
