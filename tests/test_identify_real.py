"""The real world's identification for the identified and hybrid worlds (``experiments.runtime.identify``):
the engine-gap calibration that ships with the package, and excitation logs recorded ahead of the
diagnoses."""

import json
import os

import numpy as np
import pytest

import experiments.runtime.identify as ident
from experiments.runtime.identify import (ENGINE_GAP_LOGS, ENGINE_GAP_SECONDS, ENGINE_GAP_SEED, calibrate_engines,
                                  engine_gap_key, excitation_tasks, record_excitation_task, shipped_calibration)


def _close(a, b, rtol):
    """Whether two calibration documents agree: same keys, numbers within ``rtol`` (the floating-point
    rounding of linear algebra varies with the BLAS threads and CPU at ~1e-12)."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_close(a[k], b[k], rtol) for k in a)
    if isinstance(a, list):
        return isinstance(b, list) and len(a) == len(b) and all(_close(x, y, rtol) for x, y in zip(a, b))
    if isinstance(a, float) or isinstance(b, float):
        return bool(np.isclose(a, b, rtol=rtol, atol=1e-15))
    return a == b


def test_the_shipped_engine_gap_is_for_these_engines_and_robot():
    """The package's calibrations match the pinned engines, the robot model and the code that records
    and diagnoses (else every run would record and calibrate them again: after a change in that code,
    regenerate them with ``python -m experiments.runtime.identify --engine-gap``), and only the logs they were
    computed from select them."""
    for kind in ("fixed", "floating"):
        cal = shipped_calibration(kind, seed=ENGINE_GAP_SEED, n_logs=ENGINE_GAP_LOGS, seconds=ENGINE_GAP_SECONDS)
        assert cal is not None, f"the shipped {kind} calibration is stale: {engine_gap_key(kind, seed=ENGINE_GAP_SEED, n_logs=ENGINE_GAP_LOGS, seconds=ENGINE_GAP_SECONDS)}"
        assert cal["kind"] == "sgatwalk-sysid-calibration" and cal["fixed_base"] == (kind == "fixed") and cal["n_logs"] == ENGINE_GAP_LOGS
        assert shipped_calibration(kind, seed=ENGINE_GAP_SEED + 1, n_logs=ENGINE_GAP_LOGS, seconds=ENGINE_GAP_SECONDS) is None
        assert shipped_calibration(kind, seed=ENGINE_GAP_SEED, n_logs=ENGINE_GAP_LOGS - 1, seconds=ENGINE_GAP_SECONDS) is None
    # the stepping logs' engine gap: PyBullet's ground is stiffer than MuJoCo's (a baseline compliance)
    floating = shipped_calibration("floating", seed=ENGINE_GAP_SEED, n_logs=ENGINE_GAP_LOGS, seconds=ENGINE_GAP_SECONDS)
    assert 0 < floating["baseline_model"]["ground_compliance"] < 0.01
    with pytest.raises(ValueError, match="fixed' or 'floating"):
        engine_gap_key("air", seed=0, n_logs=4, seconds=6.0)


def test_calibrate_engines_copies_the_shipped_calibration_and_recomputes_the_fixed_one(tmp_path, monkeypatch):
    """A run copies the shipped calibration without recording anything; recomputed from fresh
    recordings, the fixed-base one (seconds) comes out the same."""
    monkeypatch.setattr(ident, "_record", lambda *a, **k: pytest.fail("recorded although the calibration ships"))
    paths = calibrate_engines(str(tmp_path / "run"))
    for kind in ("fixed", "floating"):
        with open(paths[kind]) as f:
            assert json.load(f) == shipped_calibration(kind, seed=ENGINE_GAP_SEED, n_logs=ENGINE_GAP_LOGS, seconds=ENGINE_GAP_SECONDS)
    assert calibrate_engines(str(tmp_path / "run"), floating=False) == {"fixed": paths["fixed"], "floating": None}
    monkeypatch.undo()
    fresh = calibrate_engines(str(tmp_path / "fresh"), floating=False, use_shipped=False)
    assert (tmp_path / "fresh" / "fixed" / "logs" / "excite_003.parquet").exists()
    with open(fresh["fixed"]) as f:
        assert _close(json.load(f), shipped_calibration("fixed", seed=ENGINE_GAP_SEED, n_logs=ENGINE_GAP_LOGS, seconds=ENGINE_GAP_SECONDS), 1e-6)


def test_excitation_logs_recorded_ahead_are_the_ones_identify_real_uses(tmp_path, monkeypatch):
    """``excitation_tasks`` lists what ``identify_real`` still has to record; logs recorded by those
    tasks are used as they are, and a complete stage is not listed."""
    kw = {"seed": 7, "profile": "real", "n_fixed": 2, "n_floating": 1, "seconds": 3.0}
    tasks = excitation_tasks(str(tmp_path / "d0"), **kw)
    assert [(t["kind"], t["n_logs"], t["seed"], t["lumpy"]) for t in tasks] == [("fixed", 2, 7, False),
                                                                                 ("floating", 1, 57, True)]
    paths = record_excitation_task(tasks[0])
    assert len(paths) == 2 and [t["kind"] for t in excitation_tasks(str(tmp_path / "d0"), **kw)] == ["floating"]
    before = [os.stat(p).st_mtime_ns for p in paths]
    seen = []

    def fake_diagnose(logs, **k):  # stop after the fixed stage's logs are loaded
        seen.extend(lg.name for lg in logs)
        raise RuntimeError("stop")

    monkeypatch.setattr("sysid.diagnose.diagnose", fake_diagnose)
    with pytest.raises(RuntimeError, match="stop"):
        ident.identify_real(str(tmp_path / "d0"), time_budget_s=1.0, **kw)
    assert seen == ["excite_000", "excite_001"]
    assert [os.stat(p).st_mtime_ns for p in paths] == before  # not recorded again


