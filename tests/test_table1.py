"""sgatwalk table1: resume after SIGKILL, growing by methods, pairing with a baseline run."""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from experiments.cli import main

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
T1 = ["--methods", "sgat,sim", "--seeds", "2", "--trials", "3", "--popsize", "3", "--generations", "2",
      "--grounding-steps", "1", "--seconds", "0.8", "--workers", "1"]


def test_table1_resumes_after_sigkill(tmp_path):
    ref = tmp_path / "ref"
    assert main(["table1", *T1, "--out", str(ref), "--json"]) == 0
    a = json.loads((ref / "table1.json").read_text())
    assert [(r["method"], r["step"]) for r in a["rows"]] == [("theta0", 0), ("sgat", 1), ("sim", 1)]
    assert a["rows"][1]["n"] == 2 * 3 and a["rows"][0]["n"] == 3
    assert {(t["a"], t["b"]) for t in a["tests"]} == {("sgat", "sim"), ("sgat", "theta0"), ("sim", "theta0")}
    # the per-trial record (for pairing a later run trial by trial) is what the rows pool
    tr = a["trials"]
    assert set(tr) == {"theta0", "sgat|1|0", "sgat|1|1", "sim|1|0", "sim|1|1"}
    assert all(len(v["fitness"]) == len(v["fell"]) == 3 for v in tr.values())
    sg = tr["sgat|1|0"]["fitness"] + tr["sgat|1|1"]["fitness"]
    assert np.mean(sg) == pytest.approx(a["rows"][1]["fitness_mean"], abs=1e-3)
    assert sum(tr["sgat|1|0"]["fell"] + tr["sgat|1|1"]["fell"]) == a["rows"][1]["falls"]
    # each test keeps its mean difference per optimization seed (equal trials per seed: they average to the pooled one)
    # ... and the t-test over them (seeds as the units of a method-level claim)
    for t in a["tests"]:
        assert len(t["per_seed_diff"]) == 2
        assert np.mean(t["per_seed_diff"]) == pytest.approx(t["fitness"]["mean_diff"], abs=1e-3)
        sl = t["seed_level"]
        assert sl is None or (sl["n_seeds"] == 2 and sl["mean_diff"] == pytest.approx(np.mean(t["per_seed_diff"]))
                              and sl["ci"][0] <= sl["mean_diff"] <= sl["ci"][1])
    from experiments.table1.run import seed_agreement

    t = {"a": "sgat", "b": "gat", "fitness": {"mean_diff": -2.0}, "per_seed_diff": [-3.0, 1.0, -4.0]}
    assert seed_agreement(t) == "; GAT fitter on 2 of 3 optimization seeds"
    t_sl = {**t, "seed_level": {"mean_diff": -2.0, "ci": [-9.6, 5.6], "p_value": 0.33}}
    assert seed_agreement(t_sl) == "; GAT fitter on 2 of 3 optimization seeds, over seeds -2.0 [-9.6, +5.6], t-test p = 0.33"
    assert seed_agreement({**t, "fitness": {"mean_diff": 0.5}, "per_seed_diff": [1.0, 0.5, -1.0]}) == \
        "; SGAT fitter on 2 of 3 optimization seeds"
    assert seed_agreement({**t, "per_seed_diff": [-2.0]}) == seed_agreement({"a": "x", "b": "y", "fitness": {}}) == ""
    run = tmp_path / "killed"
    cmd = [sys.executable, "-m", "experiments.cli", "table1", *T1, "--out", str(run), "--json"]
    proc = subprocess.Popen(cmd, cwd=ROOT, env=dict(os.environ, PYTHONPATH=ROOT), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    t0 = time.time()
    while not (run / "opt_seed1" / "sgat" / "generations.csv").exists() and proc.poll() is None and time.time() - t0 < 300:
        time.sleep(0.05)
    assert proc.poll() is None, "the run finished before it could be killed"
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert not (run / "table1.json").exists()
    assert main(["table1", *T1, "--out", str(run), "--json"]) == 0
    b = json.loads((run / "table1.json").read_text())
    assert a["rows"] == b["rows"] and a["tests"] == b["tests"] and a["trials"] == b["trials"]
    assert np.isfinite(b["rows"][1]["fitness_mean"])
    # the same run paired with itself as a baseline (resumed: nothing is walked again) differs by nothing
    assert main(["table1", *T1, "--out", str(run), "--baseline", str(ref / "table1.json"), "--json"]) == 0
    c = json.loads((run / "table1.json").read_text())
    assert c["rows"] == a["rows"]
    assert {(t["method"], t["step"]) for t in c["baseline"]["tests"]} == {("sgat", 1), ("sim", 1)}
    own = [t for t in c["baseline"]["tests"] if "baseline_method" not in t]
    assert len(own) == 2 and all(t["fitness"]["mean_diff"] == 0 and t["falls"]["only_a"] == t["falls"]["only_b"] == 0
                                 for t in own)
    # ... and SGAT against the baseline's SIM, as a run tests them (comparisons): the within-run test again
    cross, = [t for t in c["baseline"]["tests"] if "baseline_method" in t]
    within, = [t for t in a["tests"] if (t["a"], t["b"]) == ("sgat", "sim")]
    assert (cross["method"], cross["baseline_method"]) == ("sgat", "sim")
    assert cross["fitness"]["mean_diff"] == pytest.approx(within["fitness"]["mean_diff"], abs=1e-3)  # trials kept to 4 decimals
    assert cross["per_seed_diff"] == pytest.approx(within["per_seed_diff"], abs=1e-3)


def test_table1_grows_by_methods_without_redoing_anything(tmp_path):
    """More methods given to a finished Table I run: only the new (method, seed) optimizations run (their
    real grounding walks the very walks of the others, on the same seeds), only the new gaits walk the
    real trials, the old rows stay as they were, and a noise-enveloped method is tested against its
    base method and against ANE."""
    from experiments.table1.run import comparisons

    assert comparisons(("sgat", "gat", "ane", "sgat:ane=0.05", "hybrid:ane=0.05")) == [  # only pairs of methods run
        ("sgat", "gat"), ("sgat:ane=0.05", "sgat"), ("sgat:ane=0.05", "ane"), ("hybrid:ane=0.05", "ane")]
    # hybrid against the identified sim it grounds: what the learned grounding adds to the identified physics
    assert comparisons(("identified", "hybrid", "sgat")) == [("hybrid", "sgat"), ("hybrid", "identified")]
    args = ["--seeds", "1", "--trials", "3", "--popsize", "3", "--generations", "2", "--grounding-steps", "1",
            "--seconds", "0.8", "--workers", "1"]
    run = tmp_path / "t1"
    assert main(["table1", "--methods", "sgat,ane", *args, "--out", str(run), "--json"]) == 0
    a = json.loads((run / "table1.json").read_text())
    walked = (run / "episodes.jsonl").read_text().splitlines()
    real = {p.name: p.read_bytes() for p in (run / "opt_seed0" / "sgat" / "data").glob("real_*")}
    assert real
    assert main(["table1", "--methods", "sgat,ane,sgat:ane=0.05", *args, "--out", str(run), "--json"]) == 0
    b = json.loads((run / "table1.json").read_text())
    assert b["rows"][:3] == a["rows"] and b["rows"][3]["method"] == "sgat:ane=0.05" and b["rows"][3]["n"] == 3
    now = (run / "episodes.jsonl").read_text().splitlines()
    assert now[:len(walked)] == walked and len(now) == len(walked) + 3  # 3 trials of the one new gait
    assert all(json.loads(x)["key"].startswith("sgat:ane=0.05|1|0|t") for x in now[len(walked):])
    from experiments.runtime.tasks import EpisodeTask  # noqa: F401 - the walks below are recordings of those tasks
    import pyarrow as pa
    import pyarrow.parquet as pq

    new = {p.name: p for p in (run / "opt_seed0" / "sgat_ane0.05" / "data").glob("real_*")}
    assert set(new) == set(real)  # the same gaits on the same seeds
    for name, path in new.items():  # equal column by column (the CoP is NaN while no foot touches)
        x, y = pq.read_table(path), pq.read_table(run / "opt_seed0" / "sgat" / "data" / name)
        assert x.schema.equals(y.schema, check_metadata=True)
        for c in x.column_names:
            assert np.array_equal(x[c].to_numpy(zero_copy_only=False), y[c].to_numpy(zero_copy_only=False),
                                  equal_nan=x[c].type in (pa.float32(), pa.float64())), c
    assert {(t["a"], t["b"]) for t in b["tests"]} - {(t["a"], t["b"]) for t in a["tests"]} == {
        ("sgat:ane=0.05", "sgat"), ("sgat:ane=0.05", "ane"), ("sgat:ane=0.05", "theta0")}


def test_table1_pairs_a_run_with_a_baseline_run(tmp_path, capsys):
    """compare_runs pairs (method, step, seed) gaits trial by trial: a run whose every trial is 1 point
    fitter than the baseline's and falls once less shows exactly that; runs on other trials are refused."""
    from experiments.table1.config import Table1Config
    from experiments.table1.run import baseline_verdict, compare_runs, load_baseline

    rng = np.random.default_rng(3)
    base = {"theta0": {"fitness": [1.0, 2.0], "fell": [0, 1]}}
    for s in range(2):
        base[f"sgat|1|{s}"] = {"fitness": rng.normal(0, 3, 10).tolist(), "fell": [1] * 10}
    run = {k: {"fitness": [x + (k != "theta0") for x in v["fitness"]], "fell": list(v["fell"])} for k, v in base.items()}
    run["sgat|1|0"]["fell"][4] = 0
    run["gat|1|0"] = {"fitness": [0.0] * 10, "fell": [0] * 10}  # not in the baseline: against its SGAT
    run["gat|2|0"] = {"fitness": [0.0] * 10, "fell": [0] * 10}  # no step 2 in the baseline: not compared
    g, t = compare_runs({"trials": run}, {"trials": base})
    assert (t["method"], t["step"], t["seeds"]) == ("sgat", 1, [0, 1]) and "baseline_method" not in t
    assert (g["method"], g["baseline_method"], g["step"], g["seeds"]) == ("gat", "sgat", 1, [0])
    assert g["fitness"]["mean_diff"] == pytest.approx(-np.mean(base["sgat|1|0"]["fitness"]))
    assert (g["falls"]["only_a"], g["falls"]["only_b"]) == (0, 10)  # GAT never fell, the baseline's SGAT always
    assert baseline_verdict([g])[0].startswith("step 1: GAT of this run") and "the baseline's SGAT" in baseline_verdict([g])[0]
    assert t["fitness"]["mean_diff"] == pytest.approx(1.0) and t["fitness"]["p_value"] < 1e-3
    assert (t["falls"]["only_a"], t["falls"]["only_b"]) == (0, 1)
    with pytest.raises(ValueError, match="θ0"):
        compare_runs({"trials": {**run, "theta0": {"fitness": [0.0, 2.0], "fell": [0, 1]}}}, {"trials": base})
    # a noise-enveloped method both runs have (another noise level): against the baseline's own, its base and ANE
    b2 = {**base, **{f"{m}|1|{s}": {"fitness": [float(i + s)] * 10, "fell": [0] * 10}
                     for i, m in enumerate(("ane", "sgat:ane=0.05")) for s in range(2)}}
    r2 = {"theta0": base["theta0"], **{f"sgat:ane=0.05|1|{s}": {"fitness": [5.0 + s] * 10, "fell": [0] * 10} for s in range(2)}}
    got = {t.get("baseline_method", t["method"]): t for t in compare_runs({"trials": r2}, {"trials": b2})}
    assert set(got) == {"sgat:ane=0.05", "sgat", "ane"} and got["sgat:ane=0.05"]["method"] == "sgat:ane=0.05"
    assert got["ane"]["per_seed_diff"] == [5.0, 5.0] and got["sgat:ane=0.05"]["per_seed_diff"] == [4.0, 4.0]
    assert baseline_verdict([got["ane"]])[0].endswith("this run's fitter on 2 of 2 optimization seeds)")
    # hybrid both runs have (another numerical setting of its world): against the baseline's own, SGAT and ANE
    b3 = {**b2, **{f"hybrid|1|{s}": {"fitness": [3.0] * 10, "fell": [0] * 10} for s in range(2)}}
    r3 = {"theta0": base["theta0"], **{f"hybrid|1|{s}": {"fitness": [4.0] * 10, "fell": [0] * 10} for s in range(2)}}
    got = {t.get("baseline_method", t["method"]): t for t in compare_runs({"trials": r3}, {"trials": b3})}
    assert set(got) == {"hybrid", "sgat", "ane"} and got["hybrid"]["per_seed_diff"] == [1.0, 1.0]
    assert got["ane"]["per_seed_diff"] == [4.0, 3.0]  # the baseline's ANE scored 0 and 1 on seeds 0 and 1
    path = tmp_path / "t.json"
    path.write_text(json.dumps({"command": "x", "result": {"config": {"seed": 0, "trials": 30}, "rows": [], "trials": base}}))
    assert load_baseline(str(path), Table1Config())["command"] == "x"
    with pytest.raises(ValueError, match="other real trials"):
        load_baseline(str(path), Table1Config(seed=1))
    path.write_text(json.dumps({"config": {"seed": 0, "trials": 30}, "rows": []}))
    with pytest.raises(ValueError, match="per-trial"):
        load_baseline(str(path), Table1Config())
    assert main(["table1", *T1, "--baseline", str(path), "--out", str(tmp_path / "r")]) != 0
    assert "per-trial" in capsys.readouterr().err

