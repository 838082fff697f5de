"""sgatwalk compare: fidelity results grouped by panel and ranked, on constructed results."""

import json
import os

import numpy as np
import pytest

from experiments.cli import main
from experiments.compare.run import compare, format_compare, load_results, panel_key
from experiments.fidelity.scoring import summary
from experiments.runtime.stats import brier_score, spearman

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
GAITS = ["theta0"] + [f"box{i:02d}" for i in range(7)]
REAL = np.array([-12.0, -6.0, -3.0, 0.5, 2.0, 4.0, 7.5, 9.0])
FALLS = np.array([1.0, 0.9, 0.7, 0.5, 0.4, 0.3, 0.1, 0.0])
OUTCOMES = np.array([[1.0] * k + [0.0] * (10 - k) for k in (10 * FALLS).round().astype(int)])  # 10 trials per gait


def _world(kind: str, fits: list, falls=None) -> dict:
    """A world whose draw d scores the gaits ``fits[d]`` (the figures as Fidelity computes them)."""
    draws = []
    for d, f in enumerate(fits):
        f = np.asarray(f, dtype=float)
        fr = FALLS if falls is None else np.asarray(falls, dtype=float)
        draws.append({"draw": d, "fitness": f.tolist(), "fall_rate": fr.tolist(), "rho": spearman(f, REAL),
                      "mae": float(np.mean(np.abs(f - REAL))), "bias": float(np.mean(f - REAL)),
                      "brier": brier_score(fr, OUTCOMES)})
    return {"kind": kind, "draws": draws, "summary": summary(draws)}


def _result(worlds: dict, real=REAL, seed=101) -> dict:
    return {"config": {"seed": seed, "profile": "real"}, "gaits": GAITS,
            "real": {"fitness": list(map(float, real)), "fall_rate": FALLS.tolist(), "trials": 10, "ceiling": 0.9},
            "worlds": worlds}


RNG = np.random.default_rng(0)
SHUFFLED = [RNG.permutation(REAL) for _ in range(3)]
EXACT = [REAL + 0.1 * d for d in range(3)]
NOISY = [REAL + RNG.normal(0, 4.0, len(REAL)) for _ in range(3)]


def _runs():
    a = _result({"sim": _world("sim", [REAL + 8.0], falls=np.zeros(8)),
                 "gat": _world("gat", NOISY),
                 "sgat": _world("sgat", SHUFFLED),
                 "sgat:good=1": _world("sgat", EXACT)})
    b = _result({"sim": _world("sim", [REAL + 8.0], falls=np.zeros(8)),  # the same measurement as run a's
                 "sgat": _world("sgat", NOISY)})
    other = _result({"sgat": _world("sgat", EXACT)}, real=REAL + 1.0)  # other real trials: another panel
    return [("run-a", "a.json", a), ("run-b", "b.json", b), ("run-c", "c.json", other)]


def test_compare_groups_by_panel_ranks_by_worst_rho_and_merges_shared_measurements():
    res = compare(_runs())
    assert [p["runs"] for p in res["panels"]] == [["run-a", "run-b"], ["run-c"]]
    rows = res["panels"][0]["rows"]
    names = [(r["run"], r["world"]) for r in rows]
    # the exact world first, the shuffled one last; the plain sim of both runs is one row
    assert names[0] == ("run-a", "sgat:good=1") and names[-1] == ("run-a", "sgat")
    sim = next(r for r in rows if r["world"] == "sim")
    assert sim["runs"] == ["run-a", "run-b"] and sum(r["world"] == "sim" for r in rows) == 1
    worst = [r["rho_worst"] for r in rows]
    assert worst == sorted(worst, reverse=True)
    good = rows[0]
    assert good["rho_worst"] == pytest.approx(1.0) and good["abs_bias_median"] == pytest.approx(0.1)
    assert good["bias_spread"] == pytest.approx(0.2) and good["regret_median"] == 0.0
    # paired with run a's reference SGAT (the shuffled world), draw by draw
    diffs = [1.0 - spearman(s, REAL) for s in SHUFFLED]
    assert good["vs_sgat"]["rho_diff_median"] == pytest.approx(float(np.median(diffs)))
    assert good["vs_sgat"]["wins"] == sum(d > 0 for d in diffs) and good["vs_sgat"]["pairs"] == 3
    shuffled = rows[-1]
    assert abs(shuffled["rho_median"]) < 0.8 and "vs_sgat" not in shuffled  # the reference itself
    assert "vs_sgat" not in sim


def test_compare_filters_kinds_and_keeps_the_top_rows():
    res = compare(_runs(), kinds=("sgat",), top=2)
    p = res["panels"][0]
    assert p["worlds"] == 3 and len(p["rows"]) == 2 and {r["kind"] for r in p["rows"]} == {"sgat"}
    assert "1 more" in format_compare(res)
    with pytest.raises(ValueError, match="top"):
        compare(_runs(), top=0)


def test_panel_key_tells_real_trials_apart_and_ignores_the_worlds():
    a, b, c = (r for _, _, r in _runs())
    assert panel_key(a) == panel_key(b) != panel_key(c)


def test_load_results_reads_runs_files_and_readme_results(tmp_path):
    runs = _runs()
    run_dir = tmp_path / "runs" / "fid"
    run_dir.mkdir(parents=True)
    (run_dir / "fidelity.json").write_text(json.dumps(runs[0][2]))
    (run_dir / "config.json").write_text("{}")
    saved = tmp_path / "results"
    saved.mkdir()
    (saved / "fidelity-b.json").write_text(json.dumps({"command": "sgatwalk fidelity", "result": runs[1][2]}))
    (saved / "table1.json").write_text(json.dumps({"command": "sgatwalk table1", "result": {"rows": []}}))
    got, skipped = load_results([str(run_dir), str(saved)])
    assert [label for label, _, _ in got] == ["fid", "fidelity-b"] and skipped == [str(saved / "table1.json")]
    got, _ = load_results([str(tmp_path / "runs")])  # a folder of run directories
    assert [label for label, _, _ in got] == ["fid"]
    with pytest.raises(ValueError, match="not a fidelity result"):
        load_results([str(saved / "table1.json")])
    with pytest.raises(ValueError, match="given twice"):
        load_results([str(run_dir), str(run_dir / "fidelity.json")])
    (saved / "bad.json").write_text("{not json")
    with pytest.raises(ValueError, match="bad.json: not JSON"):
        load_results([str(saved)])
    broken = json.loads(json.dumps(runs[0][2]))
    del broken["worlds"]["gat"]["draws"][1]["brier"]
    (tmp_path / "broken.json").write_text(json.dumps(broken))
    with pytest.raises(ValueError, match="broken.json: world 'gat'"):
        load_results([str(tmp_path / "broken.json")])
    other = tmp_path / "other" / "fid"  # a second run directory of the same name elsewhere
    other.mkdir(parents=True)
    (other / "fidelity.json").write_text(json.dumps(runs[1][2]))
    got, _ = load_results([str(run_dir), str(other)])
    assert [label for label, _, _ in got] == ["runs/fid", "other/fid"]
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(ValueError, match="no fidelity results"):
        load_results([str(empty)])


def test_cli_compare_prints_json_text_and_a_figure(tmp_path, capsys):
    for label, _, res in _runs():
        (tmp_path / f"{label}.json").write_text(json.dumps(res))
    png = tmp_path / "cmp.png"
    assert main(["compare", str(tmp_path / "run-a.json"), str(tmp_path / "run-c.json"), "--plot", str(png), "--json"]) == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert len(out["panels"]) == 2 and out["panels"][0]["rows"][0]["world"] == "sgat:good=1"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main(["compare", str(tmp_path / "run-a.json"), "--kinds", "sgat,gat"]) == 0
    text = capsys.readouterr().out
    assert "sgat:good=1" in text and "sim " not in text
    assert main(["compare", str(tmp_path / "run-a.json"), "--kinds", "sgat,nope"]) == 2
    assert "unknown world kind" in capsys.readouterr().err


def test_rows_carry_the_episodes_per_gait_so_runs_of_one_world_tell_apart():
    """Two runs of one world on one panel with 4 and 16 episodes per gait are two rows, each with its
    count in the row and the text table; results saved before the field show none."""
    four, sixteen = _world("sgat", NOISY), _world("sgat", EXACT)
    four["episodes"], sixteen["episodes"] = 4, 16
    res = compare([("run-4", "a.json", _result({"sgat": four})), ("run-16", "b.json", _result({"sgat": sixteen})),
                   ("old", "c.json", _result({"sgat": _world("sgat", SHUFFLED)}))])
    rows = {r["run"]: r for r in res["panels"][0]["rows"]}
    assert (rows["run-4"]["episodes"], rows["run-16"]["episodes"], rows["old"]["episodes"]) == (4, 16, None)
    text = format_compare(res)
    assert any(" run-16 " in line and "   16 " in line for line in text.splitlines())


def _episodic(kind: str, means: list, trials: np.ndarray, rng, noise=1.0, episodes=4) -> dict:
    """A world of :func:`_world` that also keeps each episode's fitness (per draw, gait, episode)."""
    w = _world(kind, means)
    for d, m in zip(w["draws"], means):
        d["fitness_episodes"] = (np.asarray(m)[:, None] + rng.normal(0, noise, (len(m), episodes))).tolist()
    return w


def test_paired_across_runs_tests_one_world_of_two_runs_on_their_shared_trials():
    rng = np.random.default_rng(5)
    trials = REAL[:, None] + rng.normal(0, 1.0, (len(REAL), 10))
    real = trials.mean(axis=1)

    def run(means, trials=trials):
        res = _result({"identified": _episodic("identified", means, trials, rng, noise=3.0)}, real=real)
        res["real"]["fitness_trials"] = trials.tolist()
        return res

    faithful = [real + rng.normal(0, 0.3, len(real)) for _ in range(3)]
    shuffled = [rng.permutation(real) for _ in range(3)]
    a, b, c = run(faithful), run(shuffled), run([f + 1e-6 for f in faithful])  # c: a measurement of its own
    res = compare([("budget2", "a.json", a), ("budget1", "b.json", b), ("again", "c.json", c)], paired=True, n_boot=300)
    (panel,) = res["panels"]
    pairs = {r["run"]: r for r in panel["paired"]}
    assert set(pairs) == {"budget1", "again"} and all(r["reference_run"] == "budget2" for r in pairs.values())
    worse = pairs["budget1"]  # shuffled gaits against a faithful world: far worse, beyond the noise
    assert worse["diff"] < -0.5 and worse["ci_panel"][1] < -0.2 and worse["p_value_panel"] < 0.01
    assert len(worse["per_draw"]) == 3
    same = pairs["again"]  # the same means, other episode noise: no difference the test can see
    assert abs(same["diff"]) < 0.1 and same["ci_panel"][0] < 0 < same["ci_panel"][1] and same["p_value_panel"] > 0.1
    text = format_compare(res)
    assert "the same world in two runs" in text and "budget1 - budget2" in text
    assert "_src" not in json.dumps(res)  # the rows stay plain JSON


def test_paired_across_runs_skips_pairs_it_cannot_pair():
    rng = np.random.default_rng(6)
    trials = REAL[:, None] + rng.normal(0, 1.0, (len(REAL), 10))
    means = [trials.mean(axis=1)] * 2
    a = _result({"sgat": _episodic("sgat", means, trials, rng)}, real=trials.mean(axis=1))
    a["real"]["fitness_trials"] = trials.tolist()
    moved = trials.copy()
    moved[0, [0, 1]] = moved[0, [1, 0]]  # the same means, other trials: pairing them would be wrong
    b = json.loads(json.dumps(a))
    b["real"]["fitness_trials"] = moved.tolist()
    old = json.loads(json.dumps(a))
    for d in old["worlds"]["sgat"]["draws"]:
        del d["fitness_episodes"]  # a result saved without the per-episode figures
    for res, eps in ((b, 1e-6), (old, 2e-6)):  # measurements of their own (the same fitness would be one row)
        for d in res["worlds"]["sgat"]["draws"]:
            d["fitness"] = [x + eps for x in d["fitness"]]
    res = compare([("a", "a.json", a), ("b", "b.json", b), ("old", "o.json", old)], paired=True, n_boot=50)
    skipped = {r["run"]: r["skipped"] for r in res["panels"][0]["paired"]}
    assert "trial by trial" in skipped["b"] and "per-episode" in skipped["old"]
    assert "skipped: the runs' real trials differ" in format_compare(res)
    assert compare([("a", "a.json", a)], paired=True)["panels"][0]["paired"] == []
    with pytest.raises(ValueError, match="n_boot"):
        compare([("a", "a.json", a)], paired=True, n_boot=0)
