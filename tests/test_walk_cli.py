"""``sgatwalk walk``: JSON result, recording, clear errors for bad input."""

import json

import pytest

from envs import Recording
from experiments import cli
from walk_engine import GaitParams

KEYS = {"speed_cm_s", "fitness", "fell", "fall_reason", "fall_time_s", "drift_m", "distance_m"}


def _run(capsys, *argv):
    code = cli.main(["walk", *argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_walk_json_and_record(tmp_path, capsys):
    theta = GaitParams(step_length=0.03).save(tmp_path / "theta.json")
    rec_path = tmp_path / "walk.parquet"
    code, out, err = _run(capsys, "--params", str(theta), "--world", "sim", "--seconds", "2", "--seed", "3",
                          "--record", str(rec_path), "--json")
    assert code == 0, err
    res = json.loads(out)
    assert KEYS <= set(res) and isinstance(res["fell"], bool)
    assert res["fitness"] == pytest.approx(res["speed_cm_s"] - 15 * res["fell"])
    assert res["params"]["step_length"] == 0.03
    rec = Recording.from_parquet(rec_path)
    assert rec.meta["params"]["step_length"] == 0.03 and rec.meta["seed"] == 3 and len(rec) == 200
    base = rec.group("gt.base")
    assert res["distance_m"] == pytest.approx(base[-1, 0] - base[0, 0])


def test_walk_human_output_defaults_to_theta0(capsys):
    """The printed line is the --json result of the same (deterministic) walk of θ0, in words."""
    from experiments.demos.walk import format_walk
    from walk_engine import GaitParams

    code, out, _ = _run(capsys, "--seconds", "1")
    code2, js, _ = _run(capsys, "--seconds", "1", "--json")
    res = json.loads(js)
    assert code == code2 == 0 and res["params"] == GaitParams().to_dict()
    assert out.strip() == format_walk(res) and f"speed {res['speed_cm_s']:.2f} cm/s" in out


def test_walk_real_world_terrain(capsys):
    code, out, err = _run(capsys, "--world", "real", "--profile", "none", "--terrain", "lumpy",
                          "--amplitude", "0.01", "--seconds", "1", "--json")
    assert code == 0, err
    res = json.loads(out)
    assert res["profile"] == "none" and res["terrain"].startswith("lumpy")


@pytest.mark.parametrize("content, words", [
    ("{not json", "not valid JSON"),
    (json.dumps({"step_period": 0.3}), "missing"),
    (json.dumps({**GaitParams().to_dict(), "step_height": 0.5}), "step_height"),
    (json.dumps({**GaitParams().to_dict(), "com_height": None}), "com_height"),
    (json.dumps({**GaitParams().to_dict(), "extra_knob": 1.0}), "extra_knob"),
])
def test_bad_params_file_is_a_one_line_error(tmp_path, capsys, content, words):
    p = tmp_path / "bad.json"
    p.write_text(content)
    code, out, err = _run(capsys, "--params", str(p), "--seconds", "1")
    assert code == 2 and out == ""
    assert words in err and err.count("\n") == 1 and "Traceback" not in err


@pytest.mark.parametrize("argv, words", [
    (["--params", "/nonexistent/theta.json"], "argument --params: no such file"),
    (["--seconds", "-1"], "--seconds"),
    (["--profile", "real"], "real world only"),
    (["--world", "real", "--profile", "nonsense", "--seconds", "0.1"], "unknown profile"),
    (["--terrain", "lumpy", "--amplitude", "-0.1"], "argument --amplitude: must be in [0, 1]"),
    (["--terrain", "lumpy", "--amplitude", "0.5"], "amplitude for lumpy must be within [0, 0.2] m"),
    (["--amplitude", "0.01"], "--amplitude needs --terrain"),
    (["--record", "/"], "is a directory"),
])
def test_bad_arguments(capsys, argv, words):
    code, _, err = _run(capsys, *argv)
    assert code == 2 and words in err


def test_walk_in_the_identified_world_and_seed_errors(tmp_path, capsys):
    rep = tmp_path / "report.json"
    rep.write_text(json.dumps({"model": {"latency": 0.02}, "base_model": {}, "effects": [
        {"family": "terrain_roughness", "value": 0.002}]}))
    code, out, err = _run(capsys, "--world", "identified", "--report", str(rep), "--seconds", "1", "--seed", "4", "--json")
    assert code == 0, err
    res = json.loads(out)
    assert res["terrain"].startswith("gaussian(sq=0.002") and res["world"] == "identified"
    for argv, words in [(["--world", "identified"], "needs --report"), (["--report", str(rep)], "needs --world identified"),
                        (["--profile", "none"], "applies to the real world only"),
                        (["--seed", "-5"], "argument --seed: must be in [0, 4294967295]")]:
        code, out, err = _run(capsys, *argv)
        assert code == 2 and words in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err
