"""The sgatwalk command line: one JSON object with --json, clear errors with exit status 2."""

import json

import pytest

from envs import Recording
from experiments.cli import build_parser, main


def test_help_lists_commands(capsys):
    assert main(["--help"]) == 0
    assert "stand" in capsys.readouterr().out


def test_stand_json_and_recording(capsys, tmp_path):
    out = tmp_path / "rec.parquet"
    rc = main(["stand", "--world", "sim,real", "--seconds", "1", "--profile", "none", "--record", str(out), "--json"])
    assert rc == 0
    res = json.loads(capsys.readouterr().out)
    assert [w["world"] for w in res["worlds"]] == ["sim", "real"]
    assert all(w["fell"] is False for w in res["worlds"])
    sim = Recording.from_parquet(res["worlds"][0]["recording"])
    assert sim.meta["world"] == "sim" and len(sim) == 100


def test_stand_table_output(capsys):
    assert main(["stand", "--world", "sim", "--seconds", "0.5", "--terrain", "lumpy", "--amplitude", "0.01"]) == 0
    out = capsys.readouterr().out
    assert "world" in out and "sim" in out and "lumpy" in out


@pytest.mark.parametrize("argv,msg", [
    (["stand", "--world", "moon"], "unknown world 'moon'"),
    (["stand", "--world", "real", "--profile", "nope"], "unknown profile 'nope'"),
    (["stand", "--seconds", "-1"], "argument --seconds: must be in (0, 3600] s"),
    (["stand", "--pose", "yoga"], "unknown pose 'yoga'"),
])
def test_bad_input_exits_2(capsys, argv, msg):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert msg in err and "Traceback" not in err


def test_every_command_has_json_flag():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    for name, p in sub.choices.items():
        assert any("--json" in a.option_strings for a in p._actions), name


def test_json_output_is_reproducible_and_timings_are_opt_in(capsys):
    argv = ["walk", "--seconds", "0.5", "--json"]
    assert main(argv) == 0
    first = capsys.readouterr().out
    assert main(argv) == 0
    assert capsys.readouterr().out == first and "wall_s" not in first  # identical runs print identical JSON
    assert main([*argv, "--timings"]) == 0
    assert json.loads(capsys.readouterr().out)["wall_s"] > 0


def test_the_command_runs_numpy_blas_with_omp_num_threads(monkeypatch):
    """``sgatwalk`` limits the BLAS already loaded (numpy imported before ``main``, as
    ``python -m tools.results save`` does) to ``OMP_NUM_THREADS`` (1 unless set): the rounding of
    threaded reductions, and so the engine-gap calibration, depends on the thread count."""
    import numpy as np
    from threadpoolctl import threadpool_info

    from experiments.runtime.executors import limit_blas_threads

    def blas_threads():
        return {i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"}

    assert np.ones(2) @ np.ones(2) == 2.0  # numpy's BLAS is loaded
    try:
        monkeypatch.setenv("OMP_NUM_THREADS", "2")
        assert limit_blas_threads() == 2 and blas_threads() == {2}
        monkeypatch.setenv("OMP_NUM_THREADS", "4,2")  # nested OpenMP settings: left as they are
        assert limit_blas_threads() == 0 and blas_threads() == {2}
        monkeypatch.delenv("OMP_NUM_THREADS")
        assert limit_blas_threads() == 1 and blas_threads() == {1}
    finally:
        monkeypatch.setenv("OMP_NUM_THREADS", "1")
        limit_blas_threads()
