"""sgatwalk optimize: tiny end-to-end runs, exact resume after SIGKILL, clear errors."""

import json
import os
import pickle
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from experiments.cli import main
from experiments.optimize.run import CheckpointError, Optimizer

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TINY = ["--grounding-steps", "1", "--popsize", "4", "--generations", "3", "--seconds", "0.6",
        "--real-episodes", "1", "--sim-episodes", "1", "--eval-trials", "2", "--select-episodes", "2", "--workers", "1", "--model-epochs", "20"]


def test_tiny_run_writes_the_run_directory(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["optimize", *TINY, "--methods", "sgat,none", "--out", str(out), "--json"]) == 0
    cap = capsys.readouterr()
    res, err = json.loads(cap.out), cap.err
    assert [(r["method"], r["step"]) for r in res["rows"]] == [("theta0", 0), ("sgat", 1), ("none", 1)]
    for r in res["rows"]:
        assert r["trials"] == 2 and 0 <= r["falls"] <= 2 and np.isfinite(r["speed_mean"])
    for f in ("config.yaml", "generations.csv", "evals.parquet", "cma_state.pkl", "fitness.png", "table.txt",
              "results.json", "thetas/sgat_step1.json", "thetas/none_step1.json", "models/sgat_step1/forward_0.pt",
              "models/sgat_step1/forward_4.pt"):
        assert (out / f).exists(), f
    import pyarrow.parquet as pq

    ev = pq.read_table(out / "evals.parquet").to_pylist()
    assert len(ev) == 2 * 3 * 4  # methods x generations x popsize (1 episode per candidate)
    assert "theta.step_period" in ev[0]
    # both methods saw the same real evaluation seeds (paired)
    rows = json.loads((out / "results.json").read_text())["rows"]
    assert [e["seed"] for e in rows[1]["episodes"]] == [e["seed"] for e in rows[2]["episodes"]]
    # each CMA-ES step's generations, measured, beside the estimate printed before them (a trial batch of
    # 4 episodes, the popsize on 1 worker: one batch per generation)
    gen = res["generation_s"]
    assert [(g["method"], g["step"], g["generations"]) for g in gen] == [("sgat", 1, 3), ("none", 1, 3)]
    for g in gen:
        assert 0 < g["min_s"] <= g["median_s"] <= g["max_s"] and g["expected_s"] > 0
    assert err.count("if none falls (1 batch(es) of 4 per worker;") == 2, err


def test_resume_after_sigkill_matches_uninterrupted(tmp_path):
    ref = tmp_path / "ref"
    assert main(["optimize", *TINY, "--methods", "sgat", "--out", str(ref), "--json"]) == 0
    run = tmp_path / "killed"
    cmd = [sys.executable, "-m", "experiments.cli", "optimize", *TINY, "--methods", "sgat", "--out", str(run), "--json"]
    env = dict(os.environ, PYTHONPATH=ROOT)
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    t0 = time.time()
    while not (run / "generations.csv").exists() and proc.poll() is None and time.time() - t0 < 300:
        time.sleep(0.05)
    assert proc.poll() is None, "the run finished before it could be killed"
    proc.send_signal(signal.SIGKILL)  # mid-generation: generation 0 is checkpointed, 1 is running
    proc.wait()
    assert not (run / "thetas" / "sgat_step1.json").exists()
    assert main(["optimize", "--resume", str(run), "--workers", "1", "--json"]) == 0
    a = json.loads((ref / "thetas" / "sgat_step1.json").read_text())
    b = json.loads((run / "thetas" / "sgat_step1.json").read_text())
    assert a == b
    ra = json.loads((ref / "results.json").read_text())["rows"]
    rb = json.loads((run / "results.json").read_text())["rows"]
    assert ra == rb


def test_command_history_grounds_the_optimization(tmp_path, capsys):
    """``--command-history 2 --matched --local-inverse``: SGAT's forward models (the real one and, for
    the matched transformer, the sim's own) see the two previous commands, the inverse model gives each
    joint's command from that joint's state alone, and CMA-ES runs in the grounded sim that feeds them
    (the lock-step batch keeps each episode's past commands)."""
    from sgat.transformer import ActionTransformer

    out = tmp_path / "run"
    assert main(["optimize", *TINY, "--methods", "sgat", "--history", "2", "--command-history", "2",
                 "--matched", "--local-inverse", "--out", str(out), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert [(r["method"], r["step"]) for r in res["rows"]] == [("theta0", 0), ("sgat", 1)]
    tr = ActionTransformer.load(out / "models" / "sgat_step1")
    assert tr.commands == 2 and tr.spec.history == 2
    assert tr.forward.n_in == 2 * tr.spec.state_dim + 3 * tr.spec.action_dim
    assert len(tr.sim_means) == tr.n_members and all(m.commands == 2 and not m.stochastic for m in tr.sim_means)
    W = tr.inverse.numpy_params()["W"][0]  # --local-inverse: the left knee's command sees no other joint
    knee = tr.spec.action_names.index("LKneePitch")
    others = [i for i, n in enumerate(tr.spec.state_names) if not n.endswith(".LKneePitch")]
    assert not np.any(W[others, knee]) and np.any(W[tr.spec.state_names.index("q.LKneePitch"), knee])
    assert np.isfinite(res["rows"][1]["select_scores"]["mean"])


def test_shadow_state_reaches_every_grounded_method(tmp_path, capsys):
    """``--shadow τ`` [s] becomes the transformer's shadow_memory in control steps for SGAT, GAT and
    hybrid; a negative τ, or τ with the matched transformer, is refused with the setting named."""
    from experiments.optimize.run import OptimizeConfig, Optimizer

    opt = Optimizer(OptimizeConfig(shadow=0.03, methods=("sgat",)), str(tmp_path / "r"), None)
    for m in ("sgat", "gat", "hybrid"):
        assert opt.grounding_config(m).shadow_memory == pytest.approx(3.0)
    assert Optimizer(OptimizeConfig(), str(tmp_path / "d"), None).grounding_config("sgat").shadow_memory == 0.0
    assert main(["optimize", "--shadow", "-1", "--out", str(tmp_path / "x")]) == 2
    assert "--shadow" in capsys.readouterr().err
    assert main(["optimize", "--shadow", "0.02", "--matched", "--out", str(tmp_path / "y")]) == 2
    assert "shadow works with the paper's transformer only" in capsys.readouterr().err


def test_the_default_method_is_hybrid_for_the_nao_and_sgat_for_the_other_robots():
    """``sgatwalk optimize`` with no ``--methods``: hybrid grounding for the NAO (nineteenth round), the
    paper's SGAT for the G1 and Talos, whose physics the diagnosis does not identify (hybrid would be
    refused for them)."""
    import argparse

    from experiments.cli.optimize import config_from_args, register
    from experiments.optimize.run import OptimizeConfig, default_methods

    assert OptimizeConfig().methods == default_methods("nao") == ("hybrid",)
    sub = argparse.ArgumentParser().add_subparsers()
    parser = register(sub)
    assert config_from_args(parser.parse_args([])).methods == ("hybrid",)
    g1 = config_from_args(parser.parse_args(["--robot", "g1"]))
    assert g1.methods == ("sgat",) and g1.robot == "g1"
    assert config_from_args(parser.parse_args(["--methods", "gat,none"])).methods == ("gat", "none")


def test_bad_input(tmp_path, capsys):
    assert main(["optimize", "--methods", "sgat,magic", "--out", str(tmp_path / "x")]) == 2
    assert "unknown method(s) ['magic']" in capsys.readouterr().err
    assert main(["optimize", "--popsize", "1", "--out", str(tmp_path / "x")]) == 2
    assert "popsize" in capsys.readouterr().err
    assert main(["optimize", "--command-history", "-1", "--out", str(tmp_path / "x")]) == 2
    assert "--command-history" in capsys.readouterr().err
    assert main(["optimize", "--resume", str(tmp_path / "nothing")]) == 2
    assert "argument --resume: no such file or directory" in capsys.readouterr().err
    bad = tmp_path / "corrupt"
    bad.mkdir()
    (bad / "cma_state.pkl").write_bytes(b"not a pickle")
    assert main(["optimize", "--resume", str(bad)]) == 2
    assert "corrupted" in capsys.readouterr().err
    old = tmp_path / "oldcma"
    old.mkdir()
    (old / "cma_state.pkl").write_bytes(pickle.dumps({"config": {}, "progress": {}, "cma_version": "0.0"}))
    with pytest.raises(CheckpointError, match="cma 0.0"):
        Optimizer.load_state(str(old))
    assert main(["optimize", "--params", str(tmp_path / "none.json"), "--out", str(tmp_path / "y")]) == 2
    assert "no such file" in capsys.readouterr().err
    # the noise envelope goes on a grounded or identified world only (the sim's own is ane), once per method
    assert main(["optimize", "--methods", "none+ane", "--out", str(tmp_path / "x")]) == 2
    assert "unknown method(s) ['none+ane']" in capsys.readouterr().err
    assert main(["optimize", "--methods", "sgat,sgat", "--out", str(tmp_path / "x")]) == 2
    assert "named twice" in capsys.readouterr().err
    assert main(["optimize", "--robot", "g1", "--methods", "hybrid+ane", "--out", str(tmp_path / "x")]) == 2
    assert "NAO only" in capsys.readouterr().err


def test_a_noise_enveloped_method_trains_its_base_grounding_in_a_noisier_world(tmp_path, capsys):
    """``sgat+ane``: the grounding is SGAT's (the same walks, fit and seeds: the same transformer), the
    training world that grounded sim with the ANE's noise on the leg targets, so its CMA-ES sees other
    fitnesses; added to a finished run with ``--resume --methods``, it reuses the run's real data and
    leaves the run's SGAT rows as they were."""
    import torch

    from experiments.optimize.run import OptimizeConfig, base_method, uses_identification

    assert (base_method("hybrid+ane"), base_method("sgat"), uses_identification("identified+ane")) == \
        ("hybrid", "sgat", True)
    opt = Optimizer(OptimizeConfig(methods=("sgat", "sgat+ane"), ane_sigma=0.07), str(tmp_path / "w"), None)
    assert opt._world_kw("sgat", 1) == ("grounded", {"transformer": str(tmp_path / "w" / "models" / "sgat_step1")})
    assert opt._world_kw("sgat+ane", 2) == ("grounded", {"transformer": str(tmp_path / "w" / "models" / "sgat+ane_step2"),
                                                        "action_noise": 0.07})
    assert opt.grounding_config("sgat+ane") == opt.grounding_config("sgat")
    out = tmp_path / "run"
    assert main(["optimize", *TINY, "--methods", "sgat", "--out", str(out), "--json"]) == 0
    before = json.loads(capsys.readouterr().out)
    real_files = sorted(p.name for p in (out / "data").glob("real_*"))
    assert main(["optimize", "--resume", str(out), "--methods", "sgat+ane", "--json"]) == 0
    after = json.loads(capsys.readouterr().out)
    assert after["rows"][:2] == before["rows"] and [r["method"] for r in after["rows"]] == ["theta0", "sgat", "sgat+ane"]
    assert sorted(p.name for p in (out / "data").glob("real_*")) == real_files  # no new real walk
    def tensors(x):  # every tensor of a saved model, in order
        return [t for v in x.values() for t in tensors(v)] if isinstance(x, dict) else [x] if torch.is_tensor(x) else []
    a = tensors(torch.load(out / "models" / "sgat_step1" / "forward_0.pt"))
    b = tensors(torch.load(out / "models" / "sgat+ane_step1" / "forward_0.pt"))
    assert a and len(a) == len(b) and all(torch.equal(x, y) for x, y in zip(a, b))
    import pyarrow.parquet as pq

    ev = pq.read_table(out / "evals.parquet").to_pylist()
    gen0 = {m: [e["fitness"] for e in ev if e["method"] == m and e["gen"] == 0] for m in ("sgat", "sgat+ane")}
    assert gen0["sgat"] != gen0["sgat+ane"]  # the same first candidates (CMA-ES seeds), a noisier world
    assert main(["optimize", "--resume", str(out), "--methods", "magic"]) == 2
    assert "unknown method(s) ['magic']" in capsys.readouterr().err


def test_wrong_shape_weights_are_rejected(tmp_path):
    """A transformer directory whose weights do not fit the grounding spec."""
    from envs import NaoSimEnv
    from sgat.models import ForwardModel, InverseModel, ModelFileError
    from experiments.runtime.grounding import grounding_spec
    from sgat.transformer import ActionTransformer

    spec = grounding_spec(NaoSimEnv())
    tr = ActionTransformer(spec, ForwardModel(24, 11), InverseModel(24, 11), alpha=0.5)
    tr.save(tmp_path / "m")
    ForwardModel(10, 11).save(tmp_path / "m" / "forward.pt")
    with pytest.raises(ModelFileError, match="10 outputs"):
        ActionTransformer.load(tmp_path / "m")
    ForwardModel(24, 12).save(tmp_path / "m" / "forward.pt")  # right outputs, one action too many
    with pytest.raises(ModelFileError, match="36 inputs, this setting needs 35"):
        ActionTransformer.load(tmp_path / "m")


def test_grounding_data_accumulates_across_steps(tmp_path):
    """Step i is grounded on the walks of θ_0 .. θ_{i-1} of its own method (GARAT's data
    accumulation); ``aggregate=False`` keeps only θ_{i-1}'s."""
    from experiments.optimize.run import OptimizeConfig
    from walk_engine import GaitParams

    th0 = GaitParams.initial().to_array()
    th1, th1_gat = th0 * 1.01, th0 * 0.99
    rows = [{"method": "theta0", "step": 0}, {"method": "sgat", "step": 1, "theta": th1.tolist()},
            {"method": "gat", "step": 1, "theta": th1_gat.tolist()}]
    opt = Optimizer(OptimizeConfig(), str(tmp_path / "a"), None, progress=False)
    opt.state = {"theta0": th0.tolist(), "rows": rows}
    pairs = opt._data_thetas("sgat", 2, th1)
    assert [j for j, _ in pairs] == [1, 2]
    np.testing.assert_array_equal(pairs[0][1], th0)
    np.testing.assert_array_equal(pairs[1][1], th1)
    assert [j for j, _ in opt._data_thetas("sgat", 1, th0)] == [1]
    opt.cfg = OptimizeConfig(aggregate=False)
    (j, th), = opt._data_thetas("gat", 2, th1_gat)
    assert j == 2 and np.array_equal(th, th1_gat)


def test_identification_budget_is_the_shared_safety_net_and_a_binding_one_is_reported(tmp_path, monkeypatch):
    """``optimize``'s identification gives each diagnosis ``IDENTIFY_BUDGET_S`` (the fidelity default
    too; 60 s bound on a slower machine and made the identified world depend on its speed) and says so
    on its log line when a diagnosis still ran out of it. Its engine-gap calibration is the testbed's
    constant (``ENGINE_GAP_SEED``, the one the package ships and ``sgatwalk fidelity`` uses), whatever
    the run's seed."""
    import experiments.optimize.run as opt_mod
    from experiments.fidelity.run import FidelityConfig
    from experiments.runtime.grounding import IDENTIFY_BUDGET_S, IDENTIFY_ROUNDS
    from experiments.runtime.identify import ENGINE_GAP_SEED
    from experiments.optimize.run import OptimizeConfig

    assert FidelityConfig().identify_budget_s == IDENTIFY_BUDGET_S >= 180.0
    assert FidelityConfig().identify_rounds == OptimizeConfig().identify_rounds == IDENTIFY_ROUNDS
    seen = {}

    def fake_identify(out_dir, **kw):
        seen.update(kw)
        return {"reports": [], "logs": 6, "seconds": 36.0, "effects": {"latency": 0.02}, "terrain_rms_height": 0.002,
                "time_budget_reached": hit, "wall_s": 1.0}

    monkeypatch.setattr(opt_mod, "identify_real", fake_identify)
    cal_seeds = []
    monkeypatch.setattr(opt_mod, "calibrate_engines",
                        lambda *a, seed, **k: cal_seeds.append(seed) or {"fixed": None, "floating": None})
    for hit in ([], ["floating"]):
        lines = []
        Optimizer(OptimizeConfig(methods=("hybrid",), seed=len(hit) + 3), str(tmp_path / f"run{len(hit)}"), None,
                  log=lines.append)._identify()
        assert seen["time_budget_s"] == IDENTIFY_BUDGET_S and seen.get("stepping_budget_s") is None
        assert seen["rounds"] == IDENTIFY_ROUNDS == 2  # experiments.runtime.grounding: one round biases the latency
        warned = [ln for ln in lines if "WARNING" in ln]
        assert len(warned) == len(hit) and all("floating diagnosis ran out" in ln for ln in warned)
    assert cal_seeds == [ENGINE_GAP_SEED, ENGINE_GAP_SEED]


def test_identified_worlds_leave_the_confounded_contact_terms_out_unless_asked_and_old_runs_resume_as_they_began(tmp_path):
    """The identified and hybrid worlds of ``optimize`` build in what ``sgatwalk fidelity``'s do (since
    its fourteenth round: without the contact terms confounded with the ground); ``--confounded-terms``
    builds them in, and a run saved before the setting existed resumes with them, as it began."""
    import argparse

    from experiments.cli.optimize import config_from_args, register
    from experiments.optimize.run import OptimizeConfig, config_from_state

    opt = Optimizer(OptimizeConfig(methods=("identified", "hybrid")), str(tmp_path / "run"), None)
    opt.state = {"identification": {"reports": ["f.json", "s.json"]}}
    assert opt._world_kw("identified", 1) == ("identified", {"identified": ["f.json", "s.json"], "identified_confounded": False})
    world, kw = opt._world_kw("hybrid", 1)
    assert world == "grounded" and kw["identified_confounded"] is False and kw["identified"] == ["f.json", "s.json"]
    ap = argparse.ArgumentParser()
    register(ap.add_subparsers())
    assert config_from_args(ap.parse_args(["optimize", "--methods", "hybrid", "--confounded-terms"])).identified_confounded
    assert not config_from_args(ap.parse_args(["optimize", "--methods", "hybrid"])).identified_confounded
    from experiments.cli import table1 as cmd_table1

    ap1 = argparse.ArgumentParser()
    cmd_table1.register(ap1.add_subparsers())
    assert cmd_table1.optimize_overrides(ap1.parse_args(["table1", "--confounded-terms"])) == {"identified_confounded": True}
    assert cmd_table1.optimize_overrides(ap1.parse_args(["table1"])) == {}
    assert cmd_table1.optimize_overrides(ap1.parse_args(["table1", "--ane-sigma", "0.025"])) == {"ane_sigma": 0.025}
    assert cmd_table1.optimize_overrides(ap1.parse_args(["table1", "--identify-rounds", "1"])) == {"identify_rounds": 1}
    assert config_from_args(ap.parse_args(["optimize", "--identify-rounds", "1"])).identify_rounds == 1
    with pytest.raises(ValueError, match="identify_rounds"):
        OptimizeConfig(identify_rounds=0).validate()
    opt.cfg = OptimizeConfig(methods=("identified",), identified_confounded=True)
    assert opt._world_kw("identified", 1)[1]["identified_confounded"] is True
    # a run state saved before the field existed resumes as it began; a new one as it was saved
    old = OptimizeConfig(methods=("identified",), hidden=(8,)).to_dict()
    del old["identified_confounded"], old["identify_rounds"]
    assert config_from_state(old).identified_confounded is True and config_from_state(old).hidden == (8,)
    assert config_from_state(old).identify_rounds == 2  # the diagnoses' rounds before the setting existed
    one = OptimizeConfig(methods=("hybrid",), identify_rounds=1)
    assert config_from_state(one.to_dict()) == one  # a run made with one round resumes with one
    assert config_from_state(OptimizeConfig(methods=("hybrid",)).to_dict()) == OptimizeConfig(methods=("hybrid",))


@pytest.mark.slow
def test_hybrid_and_identified_run_end_to_end_with_their_identification(tmp_path, capsys):
    """``--methods hybrid,identified``: excitation logs of the real world, two diagnoses, the identified
    sim, SGAT grounding on top of it, CMA-ES, and the real data each method used. The engine-gap
    calibration is the package's (a testbed constant), copied into the run: computing one (a minute on
    the faster machine, two on the slower) is tested by ``test_foot_friction_found_from_stepping_logs``
    (stepping logs) and ``tests/test_identify_real.py``."""
    out = tmp_path / "run"
    assert main(["optimize", *TINY, "--methods", "hybrid,identified", "--out", str(out), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert [(r["method"], r["step"]) for r in res["rows"]] == [("theta0", 0), ("hybrid", 1), ("identified", 1)]
    assert (out / "identified" / "fixed" / "report.json").exists() and (out / "identified" / "floating" / "report.json").exists()
    assert (out / "models" / "hybrid_step1" / "transformer.json").exists()
    rd = res["real_data"]
    assert rd["hybrid"]["walks"] == 1 and rd["hybrid"]["excitation_logs"] == 6 and rd["hybrid"]["excitation_seconds"] > 10
    assert rd["identified"]["walks"] == 0 and rd["identified"]["excitation_logs"] == 6
    assert any(f.startswith("identified_") for f in os.listdir(out / "data"))  # hybrid's sim walks: identified sim
    assert not (out / "identified" / "calibration" / "floating" / "logs").exists()  # the shipped one, not recorded


def test_cma_es_improves_the_training_world_fitness(tmp_path, capsys):
    """CMA-ES does its job: in the plain sim (deterministic), 5 generations of 8 find a gait that the
    sim scores well above θ0 on the selection episodes (θ0 walks ~14 cm/s there; optimized gaits
    reach 30+ cm/s in the sim)."""
    out = tmp_path / "run"
    assert main(["optimize", "--methods", "none", "--grounding-steps", "1", "--popsize", "8", "--generations", "5",
                 "--seconds", "3", "--eval-trials", "0", "--select-episodes", "1", "--workers", "1",
                 "--out", str(out), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    sc = next(r for r in res["rows"] if r["method"] == "none")["select_scores"]
    assert max(sc["mean"], sc["best"]) >= sc["incumbent"] + 2.0, sc
