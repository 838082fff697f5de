"""sgatwalk stochasticity: the study's summary on constructed results, and a tiny study end to end."""

import json

import numpy as np
import pytest

from experiments.cli import main
from experiments.stochasticity.run import Study, StudyConfig, summarize, table1_contrast, trend_test, verdict


def _table1(diff_per_seed, falls_a, falls_b, trials=4):
    """A Table I result whose SGAT gaits beat GAT's by ``diff_per_seed[s]`` on every trial of seed s."""
    rng = np.random.default_rng(0)
    out = {"config": {"seeds": len(diff_per_seed)}, "rows": [{"method": "sgat", "step": 1}], "trials": {}}
    for s, d in enumerate(diff_per_seed):
        base = rng.normal(0, 3, trials)
        out["trials"][f"gat|1|{s}"] = {"fitness": base.tolist(), "fell": [falls_b] * trials}
        out["trials"][f"sgat|1|{s}"] = {"fitness": (base + d).tolist(), "fell": [falls_a] * trials}
    return out


def test_contrast_is_the_mean_over_seeds_with_a_t_interval():
    (c,) = table1_contrast(_table1([1.0, 2.0, 3.0], 0, 1))
    assert c["fitness"]["mean"] == pytest.approx(2.0) and c["fitness"]["seeds"] == 3
    lo, hi = c["fitness"]["ci95"]
    assert lo == pytest.approx(2.0 - 4.303 * 1.0 / np.sqrt(3), abs=1e-3) and hi == pytest.approx(2 * 2.0 - lo)
    assert c["fall_rate"]["mean"] == -1.0 and c["fall_rate"]["ci95"] is None  # no spread: no interval
    assert table1_contrast(_table1([1.0], 0, 0))[0]["fitness"]["ci95"] is None  # one seed: no interval


def test_verdict_says_where_sgat_stands_at_each_level_and_whether_it_moved():
    levels = [{"level": 0.0, "sgat_minus_gat": table1_contrast(_table1([-1.0, 0.5, 0.2], 0, 0))},
              {"level": 3.0, "sgat_minus_gat": table1_contrast(_table1([2.0, 2.5, 3.0], 0, 1))}]
    v = verdict(levels)
    assert "level 0: SGAT's step-1 gaits are not apart from GAT's" in v[0]
    assert "level 3: SGAT's step-1 gaits are above GAT's" in v[1] and "fall rate -100 points" in v[1]
    assert v[2].startswith("from level 0 to 3 SGAT - GAT moved +2.60 fitness points, 95 % CI")
    assert v[2].endswith("SGAT pulls ahead as the randomness grows")
    # the same per-seed contrasts at both levels: no trend
    same = [{"level": lv, "sgat_minus_gat": table1_contrast(_table1([-1.0, 0.5, 0.2], 0, 0))} for lv in (0.0, 3.0)]
    assert verdict(same)[2].endswith("no trend shown at these seeds")


def test_trend_test_is_welch_on_the_per_seed_contrasts():
    from scipy import stats

    t = trend_test([0.0, 1.0, 2.0], [3.0, 5.0, 7.0])
    ref = stats.ttest_ind([3.0, 5.0, 7.0], [0.0, 1.0, 2.0], equal_var=False)
    assert t["diff"] == pytest.approx(4.0) and t["p_value"] == pytest.approx(ref.pvalue)
    assert t["ci95"][0] < 4.0 < t["ci95"][1]
    assert trend_test([1.0], [2.0, 3.0]) is None


def _parts(cfg):
    return [k for k, _, _ in Study.parts(type("S", (), {"cfg": cfg, "out": "x"})())]


def test_a_study_of_table1_runs_only_has_no_fidelity_level():
    cfg = StudyConfig(levels=(), table1_levels=(0, 3), real_seeds=0, check_episodes=0)
    cfg.validate()
    assert _parts(cfg) == ["table1", "table1"]
    with pytest.raises(ValueError, match="no level given"):
        StudyConfig(levels=()).validate()


def test_the_falls_check_follows_the_other_parts_for_grounded_methods_only():
    assert _parts(StudyConfig(levels=(0,), table1_levels=(0, 3), real_seeds=0)) == [
        "table1", "table1", "fidelity", "falls", "falls"]
    assert "falls" not in _parts(StudyConfig(levels=(0,), methods=("sim", "ane"), real_seeds=0))
    with pytest.raises(ValueError, match="check_episodes"):
        StudyConfig(check_episodes=-1).validate()


def test_a_study_saved_before_a_setting_existed_resumes_with_it(tmp_path):
    cfg = StudyConfig(levels=(0,), real_seeds=0)
    old = cfg.to_dict()
    del old["check_episodes"]
    (tmp_path / "study_config.json").write_text(json.dumps(old))
    Study(cfg, str(tmp_path), None)  # no error: the new setting only adds a part
    old["seeds"] = 9
    (tmp_path / "study_config.json").write_text(json.dumps(old))
    with pytest.raises(ValueError, match="other settings \\(seeds\\)"):
        Study(cfg, str(tmp_path), None)


def test_more_table1_methods_reopen_a_finished_table1_part(tmp_path):
    cfg = StudyConfig(levels=(0,), methods=("sgat", "gat"), real_seeds=0)
    study = Study(cfg, str(tmp_path), None)
    (tmp_path / "table1-L0").mkdir()
    (tmp_path / "table1-L0" / "table1.json").write_text(json.dumps({"config": {"methods": ["sgat", "gat"]}}))
    assert study._done("table1", str(tmp_path / "table1-L0"))
    more = Study(StudyConfig(levels=(0,), methods=("sgat", "gat", "sim"), real_seeds=0), str(tmp_path), None)
    assert not more._done("table1", str(tmp_path / "table1-L0")) and not more._done("fidelity", str(tmp_path / "x"))


def test_summary_reads_the_parts_done_so_far(tmp_path):
    cfg = StudyConfig(levels=(0, 2), real_seeds=0)
    assert cfg.table1_levels == (0.0, 2.0)
    (tmp_path / "table1-L2").mkdir()
    t1 = _table1([1.0, 2.0], 0, 0)
    t1["rows"] = [{"method": m, "step": 1, "n": 8, "fitness_mean": 0.0, "fitness_se": 1.0, "falls": 0,
                   "falls_ci95": [0, 0.3]} for m in ("sgat", "gat")]
    (tmp_path / "table1-L2" / "table1.json").write_text(json.dumps(t1))
    res = summarize(str(tmp_path), cfg)
    assert [e["level"] for e in res["levels"]] == [2.0] and res["levels"][0]["sgat_minus_gat"][0]["fitness"]["mean"] == 1.5


def test_bad_settings_are_usage_errors(capsys):
    assert main(["stochasticity", "--levels", "0,-1"]) == 2
    assert "levels must be >= 0" in capsys.readouterr().err
    assert main(["stochasticity", "--methods", "sgat,nope"]) == 2


@pytest.mark.slow
def test_a_tiny_study_runs_resumes_and_draws_its_figure(tmp_path, capsys):
    args = ["stochasticity", "--levels", "0,1", "--table1-levels", "1", "--worlds", "sim,sgat", "--gaits", "2",
            "--real-trials", "2", "--data-seeds", "2", "--episodes", "1", "--methods", "sgat,gat", "--seeds", "2",
            "--trials", "2", "--real-seeds", "0", "--popsize", "3", "--generations", "1", "--seconds", "0.8",
            "--check-episodes", "3", "--out", str(tmp_path / "s"), "--json"]
    assert main(args) == 0
    res = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert [e["level"] for e in res["levels"]] == [0.0, 1.0]
    assert {"sim", "sgat"} <= set(res["levels"][1]["fidelity"]) and res["levels"][1]["sgat_minus_gat"]
    assert "table1" not in res["levels"][0]  # Table I at level 1 only
    # the falls check: each method's last-step gaits, 3 grounded episodes per seed, beside Table I's real trials
    for e in res["levels"][1:]:
        rows = {(r["method"], r["step"]): r for r in e["table1"]}
        for m in ("sgat", "gat"):
            g = e["grounded_falls"][m]
            assert g["grounded"]["n"] == 2 * 3 and 0 <= g["grounded"]["falls"] <= 6
            last = max(st for mm, st in rows if mm == m)
            assert g["real"]["n"] == rows[(m, last)]["n"] == 4 and g["real"]["falls"] == rows[(m, last)]["falls"]
    for e in res["levels"]:
        c = e["forward_calibration"]  # SGAT's models of one draw on the other draw's real walks
        assert c["transitions"] > 0 and 0 < c["median_z_std"] < 100 and len(c["worst"]) == 3
    assert (tmp_path / "s" / "stochasticity.png").read_bytes()[:4] == b"\x89PNG"
    cfg = json.loads((tmp_path / "s" / "table1-L1" / "table1.json").read_text())["config"]
    assert cfg["optimize"]["stochasticity"] == 1.0
    assert main(args) == 0  # resumed: every part is done, the summary is the same
    again = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert again["levels"] == res["levels"]
