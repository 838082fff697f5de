"""The README's generated blocks agree with the saved results they are rendered from."""

import json

import pytest

from tools import readme
from experiments.fidelity.run import fidelity_targets, first_world


def test_readme_blocks_match_saved_results():
    assert readme.main(["--check"]) == 0, "README.md is stale: run python -m tools.readme"


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
    # tests saved with their per-seed differences and the t-test over seeds get a column each
    f = {"mean_diff": 1.0, "se_diff": 0.5, "p_value": 0.04}
    x = {"only_a": 1, "only_b": 3, "p_value": 0.6}
    res["tests"] = [{"step": 1, "a": "sgat", "b": "gat", "fitness": f, "falls": x, "per_seed_diff": [2.0, 0.5, 0.5],
                     "seed_level": {"mean_diff": 1.0, "ci": [-0.86, 2.86], "p_value": 0.18}},
                    {"step": 1, "a": "sgat", "b": "theta0", "fitness": f, "falls": x, "per_seed_diff": [1.0, 1.0, 1.0],
                     "seed_level": None}]
    readme.save("table1-x", "sgatwalk table1 --seeds 3", res, results_dir=str(tmp_path))
    out = readme.render(text, results_dir=str(tmp_path))
    assert "| per optimization seed | over seeds: mean [95 % t-interval] (p) |" in out
    assert "| +2.0, +0.5, +0.5 | +1.0 [-0.9, +2.9] (p = 0.18) |" in out and "| +1.0, +1.0, +1.0 | – |" in out


def test_link_check_finds_anchors_that_no_heading_gives(tmp_path):
    """The README check catches a link to a deleted heading (the Table I section lost its heading
    once and five links pointed nowhere): GitHub's slugs, repeated headings, ``<a id>`` tags,
    headings in code fences not counted, and links to files that are not there."""
    assert readme.github_slug("`sgatwalk table1` — the paper's Table I with power") == \
        "sgatwalk-table1--the-papers-table-i-with-power"
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "a.png").write_bytes(b"")
    text = ("# Top\n## Same\n## Same\n```bash\n# not a heading\n```\n<a id=\"tag\"></a>**x**\n"
            "[a](#top) [b](#same-1) [c](#tag) [d](docs/a.png) [e](https://example.org/x) [f](#same-2) "
            "[g](#not-a-heading) [h](docs/b.png#x) [f again](#same-2)\n")
    assert readme.anchors(text) == {"top", "same", "same-1", "tag"}
    assert readme.broken_links(text, str(tmp_path)) == ["#same-2", "#not-a-heading", "docs/b.png#x"]
    for doc in readme.DOCUMENTS:  # the README and the record of every run, as rendered
        path = readme.os.path.join(readme.ROOT, doc)
        folder = readme.os.path.dirname(path)
        assert readme.broken_links(readme.render(open(path).read(), doc_dir=folder), folder) == [], doc


def test_links_between_documents_are_checked_and_written_relative_to_each(tmp_path):
    """A link to another Markdown file's anchor counts as broken when that file gives no such anchor,
    and a rendered block's links (written relative to the repository root, e.g. a result's plot) are
    made relative to the folder of the document the block goes into."""
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "h.md").write_text("# History\n<a id=\"round-1\"></a>**Round 1.**\n")
    text = "[a](docs/h.md#round-1) [b](docs/h.md#round-2) [c](docs/h.md#history) [d](docs/h.md)\n"
    assert readme.broken_links(text, str(tmp_path)) == ["docs/h.md#round-2"]
    assert readme.broken_links("[e](../README.md#x)", str(tmp_path / "docs")) == ["../README.md#x"]
    body = "![plot](docs/compare-fidelity.png) [here](#anchor) [web](https://example.org/a.png) [code](experiments/x.py)"
    assert readme._relink(body, readme.ROOT) == body
    assert readme._relink(body, readme.os.path.join(readme.ROOT, "docs")) == (
        "![plot](compare-fidelity.png) [here](#anchor) [web](https://example.org/a.png) [code](../experiments/x.py)")


def _world(kind, rhos, briers, bias=1.0, spread=2.0):
    return {"kind": kind, "draws": [{"rho": r, "brier": b} for r, b in zip(rhos, briers)],
            "summary": {"abs_bias_median": bias, "bias": {"spread": spread}}}


def test_fidelity_targets_compare_with_the_first_gat_world_listed():
    """The reference SGAT and GAT worlds of a fidelity block are the first of their kind listed (the
    others are variants), whatever their names: a relabelled `gat:hidden=64x64` is GAT's reference."""
    res = {"real": {"ceiling": 0.9}, "worlds": {
        "sim": _world("sim", [0.4], [0.40]),
        "gat:hidden=64x64": _world("gat", [0.5, 0.6], [0.30, 0.20]),
        "sgat:hidden=64x64": _world("sgat", [0.85, 0.7], [0.25, 0.30], bias=1.5, spread=5.0),
        "sgat": _world("sgat", [0.9, 0.95], [0.10, 0.15]),
        "gat": _world("gat", [0.99, 0.99], [0.01, 0.01])}}
    assert first_world(res, "sgat") == "sgat:hidden=64x64" and first_world(res, "gat") == "gat:hidden=64x64"
    assert first_world(res, "hybrid") is None
    t = {txt: ok for txt, ok, _ in fidelity_targets(res, "sgat")}
    assert t["worst ρ over the draws ≥ 0.8, or within 0.1 of the ceiling"] and t["median |bias| ≤ 2 fitness points"]
    assert t["Brier below SIM's on every draw"] and t["Brier below GAT's on every draw"] and t["ρ ≥ GAT's on every draw"]
    t = {txt: ok for txt, ok, _ in fidelity_targets(res, "sgat:hidden=64x64")}
    assert not t["worst ρ over the draws ≥ 0.8, or within 0.1 of the ceiling"] and not t["bias spread over the draws ≤ 4"]
    assert t["Brier below SIM's on every draw"] and not t["Brier below GAT's on every draw"]  # 0.30 vs GAT's 0.20
    assert t["ρ ≥ GAT's on every draw"]
    assert fidelity_targets(res, "ane") == []


def test_fidelity_block_compares_falls_on_the_data_gait_with_the_grounding_walks():
    """The in-sample line: θ0's real fall rate, the grounding walks' own falls, and each fitted world's
    fall rate on θ0 over the draws; worlds fitted on walks of several gaits and runs saved before the
    walks' falls were recorded are left out."""
    def draw(fall0, walk_falls):
        return {"fall_rate": [fall0, 1.0], "real_walks": 4, "real_walk_falls": walk_falls}
    res = {"gaits": ["theta0", "box00"], "real": {"fall_rate": [0.6, 1.0]}, "worlds": {
        "sim": {"data_gaits": None, "draws": [{"fall_rate": [0.0, 0.0], "real_walks": 0}]},
        "sgat": {"data_gaits": 1, "draws": [draw(0.0, 1), draw(0.25, 2), draw(0.0, 2)]},
        "sgat:gaits=4": {"data_gaits": 4, "draws": [draw(1.0, 1), draw(1.0, 2), draw(1.0, 2)]},
        "sgat:real=8": {"data_gaits": 1, "draws": [dict(draw(1.0, 3), real_walks=8) for _ in range(3)]}}}
    line = "".join(readme._data_gait_falls(res))
    assert "60 % of its real trials" in line and "5 of the 12 grounding walks (1–2 of 4 per draw)" in line
    assert "`sgat` 0 % [0, 25]" in line and "gaits=4" not in line and "`sim`" not in line and "real=8" not in line
    assert "Teacher-forced" not in line  # runs saved before the replays have none
    # teacher-forced replays: worlds with the same inverse models share a clause, counts add over draws
    def rp(real_fell, with_real, without_real, q):
        return {"walks": 4, "real_fell": real_fell, "fell": with_real + without_real, "fell_with_real": with_real,
                "fell_without_real": without_real, "q_rms_rad": q, "q_rms_plain_rad": 0.035}
    same = [rp(1, 1, 0, 0.020), rp(2, 1, 1, 0.024), rp(2, 2, 2, 0.022)]
    res["worlds"]["gat"] = {"data_gaits": 1, "draws": [draw(0.0, 1), draw(0.0, 2), draw(0.0, 2)]}
    for name, replays in (("sgat", same), ("gat", same), ("hybrid", [rp(1, 0, 0, 0.03)] * 3)):
        if name == "hybrid":
            res["worlds"][name] = {"data_gaits": 1, "draws": [draw(0.5, 1), draw(0.5, 2), draw(0.5, 2)]}
        for d, r in zip(res["worlds"][name]["draws"], replays):
            d["replay"] = r
    line = "".join(readme._data_gait_falls(res))
    assert ("on 4 of the 5 walks that fell and on 3 of the 7 that did not with the inverse models of `sgat`, `gat` "
            "(leg joints 0.022 rad RMS" in line), line
    assert "on 0 of the 3 walks that fell and on 0 of the 9 that did not with the inverse models of `hybrid` (" in line
    for w in res["worlds"].values():  # a run saved before the walks' falls were recorded
        for d in w["draws"]:
            d.pop("real_walk_falls", None)
    assert readme._data_gait_falls(res) == []


def test_fidelity_block_tabulates_fidelity_against_episodes_per_gait():
    """A result with ``by_episodes`` gets one row per stochastic world and a column per count: worst ρ
    [median] (bold where the ranking target is met), the bias spread (not for a one-draw world) and,
    for SGAT, hybrid and oracle worlds, the targets met at that count; a result without it gets none."""
    from experiments.fidelity.run import _summary

    def world(kind, rhos, bias, brier=0.2):
        draws = [{"draw": i, "rho": r, "bias": b, "mae": abs(b), "brier": brier, "pick_regret": 0.0}
                 for i, (r, b) in enumerate(zip(rhos, bias))]
        return {"kind": kind, "draws": draws, "summary": _summary(draws)}

    res = {"gaits": ["a", "b", "c"], "real": {"ceiling": 0.95, "trials": 10}, "worlds": {
        "sim": {**world("sim", [0.6], [5.0], brier=0.5), "episodes": 1},
        "ane": {**world("ane", [0.3], [1.0]), "episodes": 2,
                "by_episodes": {"1": world("ane", [0.2], [1.0]), "2": world("ane", [0.3], [1.0])}},
        "oracle": {**world("oracle", [0.9, 0.85], [0.5, 1.0]), "episodes": 2,
                   "by_episodes": {"1": world("oracle", [0.6, 0.7], [0.0, 3.0]),
                                   "2": world("oracle", [0.9, 0.85], [0.5, 1.0])}}}}
    lines = readme._episodes_table(res)
    assert "| world | k = 1 | k = 2 |" in lines
    assert "| `oracle` | 0.60 [0.65], spread 3.0, 3/4 | **0.85 [0.88]**, spread 0.5, 4/4 |" in lines, lines
    assert "| `ane` | 0.20 [0.20] | 0.30 [0.30] |" in lines  # one draw: no spread, no targets
    for w in res["worlds"].values():
        w.pop("by_episodes", None)
    assert readme._episodes_table(res) == []


def test_finish_benchmark_saves_the_command_line_less_save_then_prints(monkeypatch, capsys):
    """A benchmark's ``--save NAME`` records the command that reproduces it (without ``--save``) and
    the load before it; its result prints as text, or as one JSON object with ``--json``."""
    saved = {}
    monkeypatch.setattr(readme, "save", lambda name, command, result, machine=None:
                        saved.update(name=name, command=command, result=result, machine=machine))
    res = {"text": "a table", "x": 1}
    readme.finish_benchmark(res, "benchmarks/b.py", ["--seeds", "0", "--save", "NAME"], save_name="NAME", as_json=False,
                            load_before=0.5)
    assert saved["name"] == "NAME" and saved["command"] == "python benchmarks/b.py --seeds 0" and saved["result"] is res
    assert saved["machine"]["load_before"] == 0.5
    assert capsys.readouterr().out == "a table\n"
    saved.clear()
    readme.finish_benchmark(res, "benchmarks/b.py", ["--json"], save_name=None, as_json=True, load_before=0.5)
    assert not saved and json.loads(capsys.readouterr().out) == res
