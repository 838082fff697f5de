"""The README's generated blocks agree with the saved results they are rendered from."""

import json

import pytest

from experiments import readme


def test_readme_blocks_match_saved_results():
    assert readme.main(["--check"]) == 0, "README.md is stale: run python -m experiments.readme"


def test_render_fills_a_block_from_its_results_file(tmp_path):
    res = {"config": {"seeds": 1, "trials": 2}, "rows": [
        {"method": "theta0", "step": 0, "n": 2, "speed_mean": 1.0, "speed_se": 0.5, "falls": 1, "falls_ci95": [0.1, 0.9],
         "fitness_mean": -6.5, "fitness_se": 7.5}], "tests": [], "verdict": ["nothing tested"]}
    readme.save("table1-x", "sgatwalk table1 --seeds 1", res, results_dir=str(tmp_path))
    text = "before\n<!-- results:table1-x -->\nold\n<!-- /results:table1-x -->\nafter\n"
    out = readme.render(text, results_dir=str(tmp_path))
    assert "$ sgatwalk table1 --seeds 1" in out and "| θ0 | – | 2 | 1.00 ± 0.50 | 1/2 |" in out and "old" not in out
    assert out.startswith("before\n") and out.endswith("after\n")
    assert readme.render(out, results_dir=str(tmp_path)) == out  # idempotent
    with pytest.raises(FileNotFoundError):
        readme.render("<!-- results:table1-y -->\n<!-- /results:table1-y -->", results_dir=str(tmp_path))
    with pytest.raises(KeyError):
        readme.render("<!-- results:nope -->\n<!-- /results:nope -->", results_dir=str(tmp_path))
    json.loads((tmp_path / "table1-x.json").read_text())
