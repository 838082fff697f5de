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

from walk_engine import GaitParams

from experiments.cli import main
from experiments.optimize.run import CheckpointError, Optimizer

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TINY = ["--grounding-steps", "1", "--popsize", "4", "--generations", "3", "--seconds", "0.6", "--eval-trials", "2",
        "--select-episodes", "2", "--workers", "1"]
#: A grounded world with one real and one sim walk per step and short fits (tiny runs).
SMALL = "epochs=20:real=1:sim=1"


def test_tiny_run_writes_the_run_directory(tmp_path, capsys):
    out = tmp_path / "run"
    sgat = f"sgat:{SMALL}"
    assert main(["optimize", *TINY, "--methods", f"{sgat},sim", "--out", str(out), "--json"]) == 0
    cap = capsys.readouterr()
    res, err = json.loads(cap.out), cap.err
    assert [(r["method"], r["step"]) for r in res["rows"]] == [("theta0", 0), (sgat, 1), ("sim", 1)]
    for r in res["rows"]:
        assert r["trials"] == 2 and 0 <= r["falls"] <= 2 and np.isfinite(r["speed_mean"])
    for f in ("config.yaml", "generations.csv", "evals.parquet", "cma_state.pkl", "fitness.png", "table.txt",
              "results.json", "thetas/sgat_epochs20_real1_sim1_step1.json", "thetas/sim_step1.json",
              "models/sgat_epochs20_real1_sim1_step1/forward_0.pt", "models/sgat_epochs20_real1_sim1_step1/forward_4.pt"):
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
    assert [(g["method"], g["step"], g["generations"]) for g in gen] == [(sgat, 1, 3), ("sim", 1, 3)]
    for g in gen:
        assert 0 < g["min_s"] <= g["median_s"] <= g["max_s"] and g["expected_s"] > 0
    assert err.count("if none falls (1 batch(es) of 4 per worker;") == 2, err


def test_resume_after_sigkill_matches_uninterrupted(tmp_path):
    ref = tmp_path / "ref"
    assert main(["optimize", *TINY, "--methods", f"sgat:{SMALL}", "--out", str(ref), "--json"]) == 0
    run = tmp_path / "killed"
    cmd = [sys.executable, "-m", "experiments.cli", "optimize", *TINY, "--methods", f"sgat:{SMALL}", "--out", str(run),
           "--json"]
    env = dict(os.environ, PYTHONPATH=ROOT)
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    t0 = time.time()
    while not (run / "generations.csv").exists() and proc.poll() is None and time.time() - t0 < 300:
        time.sleep(0.05)
    assert proc.poll() is None, "the run finished before it could be killed"
    proc.send_signal(signal.SIGKILL)  # mid-generation: generation 0 is checkpointed, 1 is running
    proc.wait()
    name = "sgat_epochs20_real1_sim1_step1.json"
    assert not (run / "thetas" / name).exists()
    assert main(["optimize", "--resume", str(run), "--workers", "1", "--json"]) == 0
    a = json.loads((ref / "thetas" / name).read_text())
    b = json.loads((run / "thetas" / name).read_text())
    assert a == b
    ra = json.loads((ref / "results.json").read_text())["rows"]
    rb = json.loads((run / "results.json").read_text())["rows"]
    assert ra == rb


def test_wrong_shape_weights_are_rejected(tmp_path):
    """A transformer directory whose weights do not fit the grounding spec."""
    from envs import SimWorld
    from sgat.models import ForwardModel, InverseModel, ModelFileError
    from experiments.runtime.grounding import grounding_spec
    from sgat.transformer import ActionTransformer

    spec = grounding_spec(SimWorld())
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
    opt = Optimizer(OptimizeConfig(), str(tmp_path / "a"), None)
    opt.state = {"theta0": th0.tolist(), "rows": rows}
    pairs = opt._data_thetas("sgat", 2, th1)
    assert [j for j, _ in pairs] == [1, 2]
    np.testing.assert_array_equal(pairs[0][1], th0)
    np.testing.assert_array_equal(pairs[1][1], th1)
    assert [j for j, _ in opt._data_thetas("sgat", 1, th0)] == [1]
    opt.cfg = OptimizeConfig(aggregate=False)
    (j, th), = opt._data_thetas("gat", 2, th1_gat)
    assert j == 2 and np.array_equal(th, th1_gat)


@pytest.mark.slow
def test_hybrid_and_identified_run_end_to_end_with_their_identification(tmp_path, capsys, monkeypatch):
    """``--methods hybrid,identified``: excitation logs of the real world, two diagnoses, the identified
    sim, SGAT grounding on top of it, CMA-ES, and the real data each method used. The engine-gap
    calibration is the package's (a testbed constant), copied into the run: computing one (one to two
    minutes on 2 cores) is tested by ``test_foot_friction_found_from_stepping_logs`` (stepping logs)
    and ``tests/test_identify_real.py``. This tests the wiring, not what the diagnoses find (the
    diagnosis tests do): each runs one screen/refit round within 30 s, not the default 2 within 180 s."""
    import experiments.optimize.run as optimize_run

    monkeypatch.setattr(optimize_run, "IDENTIFY_ROUNDS", 1)
    monkeypatch.setattr(optimize_run, "IDENTIFY_BUDGET_S", 30.0)
    out = tmp_path / "run"
    hybrid = f"hybrid:{SMALL}"
    assert main(["optimize", *TINY, "--methods", f"{hybrid},identified", "--out", str(out), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert [(r["method"], r["step"]) for r in res["rows"]] == [("theta0", 0), (hybrid, 1), ("identified", 1)]
    assert (out / "identified" / "fixed" / "report.json").exists() and (out / "identified" / "floating" / "report.json").exists()
    assert (out / "models" / "hybrid_epochs20_real1_sim1_step1" / "transformer.json").exists()
    rd = res["real_data"]
    assert rd[hybrid]["walks"] == 1 and rd[hybrid]["excitation_logs"] == 6 and rd[hybrid]["excitation_seconds"] > 10
    assert rd["identified"]["walks"] == 0 and rd["identified"]["excitation_logs"] == 6
    assert any(f.startswith("identified_") for f in os.listdir(out / "data"))  # hybrid's sim walks: identified sim
    assert not (out / "identified" / "calibration" / "floating" / "logs").exists()  # the shipped one, not recorded


def test_cma_es_improves_the_training_world_fitness(tmp_path, capsys):
    """CMA-ES does its job: in the plain sim (deterministic), 5 generations of 8 find a gait that the
    sim scores well above θ0 on the selection episodes (θ0 walks ~14 cm/s there; optimized gaits
    reach 30+ cm/s in the sim)."""
    out = tmp_path / "run"
    assert main(["optimize", "--methods", "sim", "--grounding-steps", "1", "--popsize", "8", "--generations", "5",
                 "--seconds", "3", "--eval-trials", "0", "--select-episodes", "1", "--workers", "1",
                 "--out", str(out), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    sc = next(r for r in res["rows"] if r["method"] == "sim")["select_scores"]
    assert max(sc["mean"], sc["best"]) >= sc["incumbent"] + 2.0, sc


def test_methods_are_training_worlds_with_their_options(tmp_path):
    """``--methods`` takes the training-world vocabulary: the paper preset adds its walks to the grounded
    worlds that do not set them; a noise envelope on a grounded world keeps that world's grounding (the
    same fit) and adds the noise to its episodes; the default is hybrid for the NAO and SGAT for the
    robots the diagnosis does not identify."""
    from experiments.optimize import OptimizeConfig, default_methods, with_preset

    assert OptimizeConfig().methods == default_methods("nao") == ("hybrid",) and default_methods("g1") == ("sgat",)
    cfg = with_preset("paper", methods=("sgat", "sgat:real=2", "ane"))
    assert cfg.methods == ("sgat:real=10:sim=10", "sgat:real=2:sim=10", "ane") and cfg.popsize == 150
    opt = Optimizer(OptimizeConfig(methods=("sgat", "sgat:ane=0.07")), str(tmp_path / "w"), None)
    plain, noisy = (opt._world_tasks(m, 2, GaitParams().to_array(), [5])[0] for m in ("sgat", "sgat:ane=0.07"))
    assert plain.transformer.endswith("sgat_step2") and noisy.transformer.endswith("sgat_ane0.07_step2")
    assert (plain.action_noise, noisy.action_noise) == (0.0, 0.07) and plain.world == noisy.world == "sim"
    from experiments.runtime.worlds import parse_world

    assert parse_world("sgat:ane=0.07").grounding_config() == parse_world("sgat").grounding_config()


def test_bad_input_is_one_line_naming_it(tmp_path, capsys):
    for argv, says in ((["--methods", "sgat,magic"], "unknown world 'magic'"), (["--popsize", "1"], "--popsize"),
                       (["--methods", "sgat:shadow=0.02"], "sgat has no option 'shadow'"),
                       (["--methods", "sgat,sgat:alpha=0.5"], "a world given twice: sgat"),
                       (["--robot", "g1", "--methods", "hybrid"], "NAO only"),
                       (["--methods", "sim:ane=0.05"], "sim has no option 'ane'"),
                       (["--resume", str(tmp_path / "nothing")], "no such directory"),
                       (["--params", str(tmp_path / "none.json")], "no such file")):
        assert main(["optimize", *argv, "--out", str(tmp_path / "x")]) == 2, argv
        err = capsys.readouterr().err
        assert says in err and err.count("\n") == 1, (argv, err)
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


def test_identification_uses_the_shared_budget_and_calibration_and_warns_when_a_diagnosis_runs_out(tmp_path, monkeypatch):
    """``optimize``'s identification gives each diagnosis ``IDENTIFY_BUDGET_S`` in ``IDENTIFY_ROUNDS``
    rounds, copies the testbed's engine-gap calibration (``ENGINE_GAP_SEED``) whatever the run's seed,
    and says so on its log line when a diagnosis still ran out of its budget."""
    import experiments.optimize.run as opt_mod
    from experiments.runtime.grounding import IDENTIFY_BUDGET_S, IDENTIFY_ROUNDS
    from experiments.runtime.identify import ENGINE_GAP_SEED
    from experiments.runtime.progress import Reporter

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
        opt_mod.identify(str(tmp_path / f"run{len(hit)}"), seed=len(hit) + 3, reporter=Reporter.to(lines.append))
        assert seen["time_budget_s"] == IDENTIFY_BUDGET_S and seen["rounds"] == IDENTIFY_ROUNDS == 2
        warned = [ln for ln in lines if "WARNING" in ln]
        assert len(warned) == len(hit) and all("floating diagnosis ran out" in ln for ln in warned)
    assert cal_seeds == [ENGINE_GAP_SEED, ENGINE_GAP_SEED]
