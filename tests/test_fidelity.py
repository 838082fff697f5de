"""sgatwalk fidelity and table1: world parsing, a tiny end-to-end run with resume, bad input."""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from experiments.cli import main
from experiments.runtime.executors import SerialExecutor
from experiments.fidelity.run import FidelityConfig, _summary, episode_counts, episodes_rows, episodes_view, parse_world

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TINY = ["--gaits", "2", "--real-trials", "2", "--data-seeds", "2", "--episodes", "2", "--seconds", "1.5",
        "--workers", "1"]


def test_parse_world_options():
    w = parse_world("sgat:ensemble=3:alpha=0.7:real=6:inverse_command=1:hidden=32x32")
    assert (w.kind, w.real_walks, w.grounding.ensemble, w.grounding.alpha, w.grounding.inverse_command,
            w.grounding.hidden) == ("sgat", 6, 3, 0.7, True, (32, 32))
    assert parse_world("gat").grounding.method == "gat" and parse_world("sim").grounding is None
    assert parse_world("ane:sigma=0.02").sigma == 0.02
    h = parse_world("hybrid:method=gat:state=legs+imu:history=2:gaits=3")
    assert (h.grounding.method, h.state, h.history, h.data_gaits, h.grounding.alpha) == ("gat", "legs+imu", 2, 3, 0.1)
    assert not parse_world("identified:ground=0").identified_ground and not parse_world("identified:terms=0").identified_terms
    # a world's cache key changes with any setting, not with its name; options at their defaults hash as before
    assert parse_world("sgat").key == parse_world("sgat:alpha=0.5:ensemble=5").key != parse_world("sgat:alpha=0.4").key
    assert parse_world("sgat").key == parse_world("sgat:mixture=1:memory=0").key
    m = parse_world("sgat:mixture=3:memory=0.5")
    assert (m.grounding.components, m.grounding.noise_memory) == (3, pytest.approx(50.0))  # 0.5 s at 100 Hz
    assert len({parse_world(w).key for w in ("sgat", "sgat:mixture=3", "sgat:memory=0.5", "sgat:mixture=3:memory=0.5")}) == 4
    assert parse_world("sgat:hidden=0").grounding.hidden == () and parse_world("gat:hidden=16x8").grounding.hidden == (16, 8)
    lm = parse_world("sgat:local=1:matched=1:zero=1").grounding
    assert lm.local_inverse and lm.matched and lm.zero_init and not parse_world("sgat").grounding.local_inverse
    assert parse_world("sgat:local=0").key == parse_world("sgat").key != parse_world("sgat:local=1").key
    assert parse_world("sgat:dad=2").grounding.dad_iterations == 2 and parse_world("hybrid:dad=1").grounding.dad_iterations == 1
    assert parse_world("sgat:dad=0").key == parse_world("sgat").key != parse_world("sgat:dad=1").key
    assert parse_world("hybrid:gate=0.9").grounding.gate == 0.9 and parse_world("gat:gate=0.5").grounding.gate == 0.5
    assert parse_world("hybrid:gate=0").key == parse_world("hybrid").key != parse_world("hybrid:gate=0.9").key
    # delay: fixed, or hybrid's identified latency per draw; 0 hashes as the paper's world
    assert parse_world("sgat:delay=2").grounding.delay == 2 and parse_world("hybrid:delay=auto").delay_auto
    assert parse_world("hybrid:delay=0").key == parse_world("hybrid").key != parse_world("hybrid:delay=auto").key
    for bad, words in [("sgat:delay=auto", "hybrid only"), ("sgat:delay=2:matched=1", "delay works with the paper"),
                       ("gat:delay=x", "bad value")]:
        with pytest.raises(ValueError, match=words):
            parse_world(bad)
    assert parse_world("identified:stepping=9").stepping_logs == 9 and parse_world("hybrid:stepping=6").stepping_logs == 6
    assert parse_world("identified").key != parse_world("identified:stepping=9").key != parse_world("identified:stepping=6").key
    # since the fourteenth round the identified worlds leave the confounded contact terms out by default
    assert parse_world("hybrid:confounded=1").identified_confounded and not parse_world("identified").identified_confounded
    assert parse_world("identified:confounded=0").key == parse_world("identified").key != parse_world("identified:confounded=1").key
    # ... and every cached world keeps its meaning: the keys are the ones those worlds had before
    # (plain identified / hybrid of the earlier rounds, which built those terms in, and confounded=0)
    assert parse_world("identified:confounded=1").key == "identified-93b905ef6f"
    assert parse_world("hybrid:confounded=1").key == "hybrid-1d80807e52"
    assert parse_world("identified").key == "identified-ab4e2aa64c" and parse_world("hybrid").key == "hybrid-f22aa61161"
    # ... and the worlds the setting does not concern keep theirs
    assert [parse_world(w).key for w in ("sim", "ane", "gat", "sgat")] == \
        ["sim-48bb3e43b8", "ane-eaeef1c08a", "gat-833017b206", "sgat-5b13614641"]
    for bad, words in [("magic", "unknown world"), ("sgat:foo=1", "unknown option"), ("sgat:alpha=x", "bad value"),
                       ("sim:alpha=1", "unknown option"), ("sgat:ensemble", "key=value"), ("sgat:alpha=3", "alpha"),
                       ("sgat:real=0", "real_walks"), ("sgat:state=arms", "state"), ("hybrid:method=ane", "method"),
                       ("identified:alpha=1", "unknown option"), ("sgat:mixture=0", "components"),
                       ("sgat:memory=-1", "noise_memory"), ("ane:mixture=2", "unknown option"), ("sgat:hidden=0x16", "hidden"),
                       ("sgat:local=1:hidden=64x64", "linear models"), ("identified:stepping=-1", "stepping"),
                       ("sgat:stepping=9", "unknown option"), ("identified:stepping=x", "bad value"),
                       ("sgat:dad=-1", "dad_iterations"), ("identified:dad=1", "unknown option"),
                       ("hybrid:gate=2", "quantile"), ("sgat:gate=0.9:ensemble=1", "at least 2 members"),
                       ("identified:gate=0.9", "unknown option")]:
        with pytest.raises(ValueError, match=words):
            parse_world(bad)
    with pytest.raises(ValueError, match="repeats"):
        FidelityConfig(worlds=("sgat", "sgat")).validate()
    with pytest.raises(ValueError, match="real_trials"):
        FidelityConfig(real_trials=1).validate()
    with pytest.raises(ValueError, match="identify_rounds"):
        FidelityConfig(identify_rounds=0).validate()


def test_identify_rounds_is_part_of_a_runs_identity_and_old_runs_keep_theirs(tmp_path):
    """A run with the default two rounds per diagnosis keeps the config every run before the setting
    saved (no key), so those resume; a run made with one round records it, and resuming it with two
    is refused (its identifications were made with one)."""
    from experiments.runtime.rundir import EpisodeLog

    old = FidelityConfig().to_dict()
    assert FidelityConfig().identify_rounds == 2 and "identify_rounds" not in old
    EpisodeLog(str(tmp_path / "old"), old, "fidelity run", say=lambda s: None)
    EpisodeLog(str(tmp_path / "old"), FidelityConfig().to_dict(), "fidelity run", say=lambda s: None)
    one = FidelityConfig(identify_rounds=1).to_dict()
    assert one["identify_rounds"] == 1
    EpisodeLog(str(tmp_path / "one"), one, "fidelity run", say=lambda s: None)
    with pytest.raises(ValueError, match="identify_rounds"):
        EpisodeLog(str(tmp_path / "one"), FidelityConfig().to_dict(), "fidelity run", say=lambda s: None)


def test_identifications_with_more_stepping_logs_share_the_fixed_base_stage(tmp_path, monkeypatch):
    """``identified:stepping=N`` identifies each draw again from N stepping logs (another folder, the
    same seed) on the draw's own fixed-base stage, and reports the excitation data it used."""
    import experiments.fidelity.run as fid

    calls = []

    def fake_identify(out_dir, *, n_fixed, n_floating, fixed_dir, seed, rounds, **kw):
        calls.append((os.path.relpath(out_dir, tmp_path), n_floating, os.path.relpath(fixed_dir, tmp_path), seed))
        assert rounds == 1  # the run's identify_rounds (default experiments.runtime.grounding.IDENTIFY_ROUNDS, 2)
        rep = os.path.join(out_dir, "floating", "report.json")  # a ground compliance standing in for the ground
        os.makedirs(os.path.dirname(rep), exist_ok=True)
        comp = {"family": "ground_compliance", "joints": [], "links": [], "value": 0.03}
        with open(rep, "w") as f:
            json.dump({"model": {"ground_compliance": 0.03}, "base_model": {"latency": 0.02}, "uncertain": [comp],
                       "effects": [{"family": "terrain_roughness", "value": 0.002}],
                       "indistinguishable": [{"a": "ground_compliance", "b": "terrain_roughness"}]}, f)
        return {"reports": [rep], "logs": n_fixed + n_floating,
                "seconds": 6.0 * (n_fixed + n_floating), "effects": {"ground_compliance": 0.03, "latency": 0.02},
                "terrain_rms_height": 0.002 + 0.0001 * n_floating, "wall_s": 0.0}

    recorded = []
    monkeypatch.setattr(fid, "identify_real", fake_identify)
    monkeypatch.setattr(fid, "record_excitation_task", lambda t: recorded.append(t) or [])
    monkeypatch.setattr(fid, "calibrate_engines", lambda *a, **k: {"fixed": None, "floating": None})
    run = fid.Fidelity(FidelityConfig(worlds=("sim", "identified", "identified:stepping=9", "identified:confounded=1"),
                                      data_seeds=2, identify_rounds=1), str(tmp_path), executor=SerialExecutor())
    prep = run.prepare()
    # every excitation log set is recorded before the diagnoses, side by side on the executor: each
    # draw's fixed-base stage once (the counts share it), a stepping stage per draw and count
    rec = sorted((os.path.relpath(t["out_dir"], tmp_path), t["n_logs"], t["fixed_base"]) for t in recorded)
    assert rec == sorted([(f"identified/d{d}/fixed/logs", 3, True) for d in (0, 1)]
                         + [(f"identified/d{d}/floating/logs", 3, False) for d in (0, 1)]
                         + [(f"identified/d{d}_stepping9/floating/logs", 9, False) for d in (0, 1)])
    by_dir = {c[0]: c for c in calls}
    assert sorted(by_dir) == ["identified/d0", "identified/d0_stepping9", "identified/d1", "identified/d1_stepping9"]
    for d in (0, 1):
        plain, more = by_dir[f"identified/d{d}"], by_dir[f"identified/d{d}_stepping9"]
        assert (plain[1], more[1]) == (3, 9)
        assert plain[2] == more[2] == f"identified/d{d}/fixed" and plain[3] == more[3]  # one fixed stage, one seed
        assert prep["identified"][d]["excitation_logs"] == 6 and prep["identified:stepping=9"][d]["excitation_logs"] == 12
        assert prep["identified:stepping=9"][d]["terrain_rms_height"] == pytest.approx(0.0029)
    assert by_dir["identified/d0"][3] != by_dir["identified/d1"][3]  # draws are independent
    assert prep["sim"][0]["identified"] is None
    # each world lists the terms it builds in: the default leaves out the contact term confounded with the ground
    assert prep["identified:confounded=1"][0]["effects"] == {"ground_compliance": 0.03, "latency": 0.02}
    assert prep["identified"][0]["effects"] == {"latency": 0.02}


def test_a_walk_fitted_identified_world_adds_the_fitted_actuation_to_its_draws_reports(tmp_path, monkeypatch):
    """``identified:walkfit=actuation``: per draw, the actuation fitted to the draw's real walks of θ0 (the
    walks SGAT's grounding records, ``real_d<draw>``) is one more report over the diagnosis's, and the
    world counts those walks as its real data besides the excitation logs."""
    import experiments.fidelity.run as fid
    import experiments.runtime.walkfit as walkfit

    def fake_identify(out_dir, *, n_fixed, n_floating, **kw):
        rep = os.path.join(out_dir, "floating", "report.json")
        os.makedirs(os.path.dirname(rep), exist_ok=True)
        with open(rep, "w") as f:
            json.dump({"model": {"latency": 0.02}, "base_model": {}, "effects": []}, f)
        return {"reports": [rep], "logs": n_fixed + n_floating, "seconds": 36.0, "effects": {"latency": 0.02},
                "terrain_rms_height": 0.0, "wall_s": 0.0}

    fits = []

    def fake_fit(real, reports, theta, out_dir, executor, *, seeds, seconds, grid, identified_confounded=True, **kw):
        assert grid == "actuation"
        fits.append(([r.meta["seed"] for r in real], list(reports), seeds))
        path = os.path.join(out_dir, "report.json")
        os.makedirs(out_dir, exist_ok=True)
        with open(path, "w") as f:
            json.dump({"model": {"torque_limit": 0.8, "latency": 0.01}, "base_model": {}, "effects": []}, f)
        return {"terms": {"torque_limit": 0.8, "latency": 0.01}, "path": path}

    monkeypatch.setattr(fid, "identify_real", fake_identify)
    monkeypatch.setattr(fid, "record_excitation_task", lambda t: [])
    monkeypatch.setattr(fid, "calibrate_engines", lambda *a, **k: {"fixed": None, "floating": None})
    monkeypatch.setattr(walkfit, "fit_walk_terms", fake_fit)
    assert parse_world("identified:walkfit=ground").walkfit == "ground"
    assert parse_world("hybrid:walkfit=actuation").key != parse_world("hybrid:walkfit=ground").key != parse_world("hybrid").key
    assert parse_world("identified:walkfit=0").key == parse_world("identified").key
    with pytest.raises(ValueError, match="unknown option"):
        parse_world("sgat:walkfit=ground")
    with pytest.raises(ValueError, match="actuation or ground"):
        parse_world("identified:walkfit=1")
    run = fid.Fidelity(FidelityConfig(worlds=("identified", "identified:walkfit=actuation"), data_seeds=2, seconds=1.0),
                       str(tmp_path), executor=SerialExecutor())
    prep = run.prepare()
    assert len(fits) == 2 and fits[0][2] != fits[1][2]  # one fit per draw, on sim seeds of its own
    for d in (0, 1):
        plain, fitted = prep["identified"][d], prep["identified:walkfit=actuation"][d]
        assert fitted["identified"][:-1] == plain["identified"] == fits[d][1]
        # the fit of the default world (without the confounded contact terms: the "x" of its folder)
        assert fitted["identified"][-1].endswith(os.path.join(f"d{d}", "walkfit_actuationx", "report.json"))
        assert fitted["effects"] == {"latency": 0.01, "torque_limit": 0.8} and plain["effects"] == {"latency": 0.02}
        assert fitted["real_walks"] == 4 and plain["real_walks"] == 0 and fitted["excitation_logs"] == 6
        assert all(os.path.basename(p).startswith(f"real_d{d}_") for p in fitted["real_paths"])
        assert fits[d][0] == fid._seeds(run.cfg.seed, fid._GROUND_REAL, d, n=4)  # SGAT's grounding walks of the draw


def test_servo_fitted_identified_worlds_add_the_common_kp_scale_to_their_draws_reports(tmp_path, monkeypatch):
    """``identified:servo=air`` / ``servo=stepping``: per draw, one kp scale for every servo fitted to
    the draw's in-air logs over the in-air diagnosis (one fit per draw, whatever the stepping logs) or
    to its stepping logs over the whole identification (no confounded contact terms under it by
    default) is one more report over the diagnosis's; ``servo=staged`` diagnoses the stepping logs
    again with the in-air fit under them (a folder of its own, the draw's fixed-base stage; the fit's
    report between the two stages'), ``servo=refit`` the same on the in-air fit that refits the in-air
    model's terms too (another fit and folder). The option leaves every other world's cache key alone."""
    import experiments.fidelity.run as fid

    calls = []

    def fake_identify(out_dir, *, n_fixed, n_floating, fixed_dir, base_terms=None, **kw):
        calls.append((os.path.relpath(out_dir, tmp_path), os.path.relpath(fixed_dir, tmp_path),
                      {t.label(): v for t, v in (base_terms or {}).items()}))
        reps = [os.path.join(fixed_dir, "report.json"), os.path.join(out_dir, "floating", "report.json")]
        for rep in reps:
            os.makedirs(os.path.dirname(rep), exist_ok=True)
            with open(rep, "w") as f:
                json.dump({"model": {"latency": 0.02}, "base_model": {}, "effects": []}, f)
        return {"reports": reps, "logs": n_fixed + n_floating, "seconds": 36.0, "effects": {"latency": 0.02},
                "terrain_rms_height": 0.0, "wall_s": 0.0}

    fits = []

    def fake_fit(reports, logs_dir, calibration, out_path, *, confounded, refit=False):
        fits.append(([os.path.relpath(r, tmp_path) for r in reports], os.path.relpath(logs_dir, tmp_path), calibration,
                     confounded, refit))
        model = {"pd_gain_all": 0.9, **({"latency": 0.015} if refit else {})}
        os.makedirs(os.path.dirname(out_path), exist_ok=True)
        with open(out_path, "w") as f:
            json.dump({"model": model, "base_model": {}, "effects": [],
                       "servo_fit": {"heldout_cost_before": 10.0, "heldout_cost_after": 8.0}}, f)
        return {"value": 0.9, "heldout_cost_before": 10.0, "heldout_cost_after": 8.0, "path": out_path,
                **({"refitted": {"latency": [0.02, 0.015]}} if refit else {})}

    monkeypatch.setattr(fid, "identify_real", fake_identify)
    monkeypatch.setattr(fid, "record_excitation_task", lambda t: [])
    monkeypatch.setattr(fid, "calibrate_engines", lambda *a, **k: {"fixed": "cal_fixed.json", "floating": "cal_floating.json"})
    monkeypatch.setattr(fid, "fit_servo_gain", fake_fit)
    assert parse_world("hybrid:servo=air").servo == "air" and not parse_world("hybrid").servo
    assert parse_world("identified:servo=0").key == parse_world("identified").key == "identified-ab4e2aa64c"
    assert len({parse_world(f"identified:servo={v}").key for v in ("air", "staged", "stepping", "refit", "0")}) == 5
    with pytest.raises(ValueError, match="unknown option"):
        parse_world("sgat:servo=air")
    with pytest.raises(ValueError, match="air or staged or stepping or refit"):
        parse_world("identified:servo=1")
    worlds = ("identified", "identified:servo=air", "identified:servo=air:stepping=6", "identified:servo=stepping",
              "identified:servo=staged", "identified:servo=refit")
    run = fid.Fidelity(FidelityConfig(worlds=worlds, data_seeds=2, seconds=1.0), str(tmp_path), executor=SerialExecutor())
    prep = run.prepare()
    air = [f for f in fits if f[2] == "cal_fixed.json"]
    assert [f[:2] + f[4:] for f in air] == [([f"identified/d{d}/fixed/report.json"], f"identified/d{d}/fixed/logs", r)
                                            for d in (0, 1) for r in (False, True)]
    assert [f[1:] for f in fits if f not in air] == [(f"identified/d{d}/floating/logs", "cal_floating.json", False, False)
                                                     for d in (0, 1)]
    for d in (0, 1):
        plain = prep["identified"][d]
        for w, where in (("identified:servo=air", "servo_air"), ("identified:servo=air:stepping=6", "servo_air"),
                         ("identified:servo=stepping", "servo_fitx")):
            assert prep[w][d]["identified"][-1].endswith(os.path.join(f"d{d}", where, "report.json"))
            assert prep[w][d]["effects"] == {"latency": 0.02, "pd_gain_all": 0.9}
            assert prep[w][d]["servo_fit"] == {"heldout_cost_before": 10.0, "heldout_cost_after": 8.0}
        assert prep["identified:servo=stepping"][d]["identified"][:-1] == plain["identified"]
        assert plain["effects"] == {"latency": 0.02}
        for w, fit, folder in (("staged", "air", "servo"), ("refit", "air_refit", "servorefit")):
            staged = prep[f"identified:servo={w}"][d]["identified"]
            assert [os.path.relpath(p, tmp_path) for p in staged] == [f"identified/d{d}/fixed/report.json",
                                                                      f"identified/d{d}/servo_{fit}/report.json",
                                                                      f"identified/d{d}_{folder}/floating/report.json"]
        # the stepping diagnosis (its fake model: latency 0.02) overrides the refitted in-air latency under it
        assert prep["identified:servo=refit"][d]["effects"] == {"latency": 0.02, "pd_gain_all": 0.9}
    assert sorted(c for c in calls if "_servo" in c[0]) == sorted(
        [(f"identified/d{d}_servo", f"identified/d{d}/fixed", {"pd_gain_all": 0.9}) for d in (0, 1)]
        + [(f"identified/d{d}_servorefit", f"identified/d{d}/fixed", {"pd_gain_all": 0.9, "latency": 0.015})
           for d in (0, 1)])
    assert all(c[2] == {} for c in calls if "_servo" not in c[0])
    with pytest.raises(ValueError, match="stepping logs"):
        fid.Fidelity(FidelityConfig(worlds=("identified:servo=stepping:stepping=0",), data_seeds=1, seconds=1.0),
                     str(tmp_path / "b"), executor=SerialExecutor()).prepare()


def test_more_episodes_per_gait_extend_a_run_as_a_fresh_run_would_walk_them(tmp_path, capsys):
    """A run resumed with another --episodes walks only the episodes it lacks, and its result is a
    fresh run's with that count: the first k episode seeds of a gait are those of a k-episode run."""
    base = ["fidelity", "--gaits", "2", "--real-trials", "2", "--seconds", "1.0", "--workers", "1",
            "--worlds", "sim", "ane", "--json"]
    grown, fresh = tmp_path / "grown", tmp_path / "fresh"
    assert main([*base, "--episodes", "2", "--out", str(grown)]) == 0
    two = json.loads(capsys.readouterr().out)
    n2 = len((grown / "episodes.jsonl").read_text().splitlines())
    assert main([*base, "--episodes", "3", "--out", str(grown)]) == 0
    grown_res = json.loads(capsys.readouterr().out)
    assert len((grown / "episodes.jsonl").read_text().splitlines()) == n2 + 3  # one more ane episode per gait
    assert main([*base, "--episodes", "3", "--out", str(fresh)]) == 0
    fresh_res = json.loads(capsys.readouterr().out)
    assert grown_res["worlds"] == fresh_res["worlds"] and grown_res["real"] == fresh_res["real"]
    assert grown_res["worlds"]["ane"]["episodes"] == 3 and two["worlds"]["ane"]["episodes"] == 2
    assert main([*base, "--episodes", "2", "--out", str(grown)]) == 0  # fewer: the first two again
    assert json.loads(capsys.readouterr().out)["worlds"] == two["worlds"]
    assert json.loads((grown / "config.json").read_text())["episodes"] == 2
    # the curve over episodes per gait: the first 2 of 3 episodes score as the 2-episode run does
    ane3, ane2 = grown_res["worlds"]["ane"], two["worlds"]["ane"]
    assert sorted(ane3["by_episodes"], key=int) == ["1", "2", "3"] and "by_episodes" not in grown_res["worlds"]["sim"]
    for key in ("rho", "mae", "bias", "brier", "pick_regret"):
        assert ane3["by_episodes"]["2"]["draws"][0][key] == pytest.approx(ane2["draws"][0][key], nan_ok=True)
        assert ane3["by_episodes"]["3"]["draws"][0][key] == pytest.approx(ane3["draws"][0][key], nan_ok=True)
    view = episodes_view(grown_res, 2)
    assert view["worlds"]["ane"]["summary"] == {k: v for k, v in ane2["summary"].items() if k != "world_ceiling"}
    assert view["worlds"]["sim"] == grown_res["worlds"]["sim"]


def test_episode_counts_and_the_view_at_k_episodes():
    """The counts a world is scored at (powers of two below its own, and its own), and a result read
    at k episodes: deterministic worlds as they are, stochastic ones from their first k episodes, those
    measured with fewer left out; the targets then judge the k-episode figures."""
    assert episode_counts(1) == [] and episode_counts(2) == [1, 2] and episode_counts(6) == [1, 2, 4, 6]
    assert episode_counts(16) == [1, 2, 4, 8, 16]

    def world(kind, rhos, bias, brier=0.2):
        draws = [{"draw": i, "rho": r, "bias": b, "mae": abs(b), "brier": brier, "pick_regret": 0.0}
                 for i, (r, b) in enumerate(zip(rhos, bias))]
        return {"kind": kind, "draws": draws, "summary": _summary(draws)}

    # a world whose ranking and bias settle with more episodes: 0.5 worst at one, 0.9 at four
    noisy = {**world("sgat", [0.9, 0.92], [1.0, 1.5]), "episodes": 4,
             "by_episodes": {"1": world("sgat", [0.5, 0.7], [-3.0, 3.0]), "4": world("sgat", [0.9, 0.92], [1.0, 1.5])}}
    res = {"gaits": ["a", "b", "c"], "real": {"ceiling": 0.95, "trials": 10}, "worlds": {
        "sim": {**world("sim", [0.6], [5.0], brier=0.5), "episodes": 1},
        "gat": {**world("gat", [0.6, 0.6], [2.0, 2.0], brier=0.3), "episodes": 1},
        "sgat": noisy, "ane": {**world("ane", [0.3], [0.0]), "episodes": 2}}}
    one = episodes_view(res, 1)
    assert set(one["worlds"]) == {"sim", "gat", "sgat"} and one["worlds"]["sim"] is res["worlds"]["sim"]
    assert one["worlds"]["sgat"]["summary"]["rho"]["min"] == 0.5 and one["worlds"]["sgat"]["episodes"] == 1
    assert set(episodes_view(res, 2)["worlds"]) == {"sim", "gat", "ane"}  # ane ran 2 episodes and has no curve
    rows = {r["episodes"]: r for r in episodes_rows(res) if r["world"] == "sgat"}
    assert (rows[1]["ranking_met"], rows[4]["ranking_met"]) == (False, True)
    assert rows[1]["bias_spread"] == pytest.approx(6.0) and rows[4]["targets_met"] == rows[4]["targets"] == 6
    with pytest.raises(ValueError, match="episodes per gait"):
        episodes_view(res, 0)


def test_tiny_fidelity_run_and_resume(tmp_path, capsys):
    out = tmp_path / "fid"
    args = ["fidelity", *TINY, "--worlds", "sim", "sgat", "gat", "--out", str(out), "--timings", "--json"]
    assert main(args) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["gaits"][0] == "theta0" and len(res["gaits"]) == 3
    assert len(res["worlds"]["sim"]["draws"]) == 1 and len(res["worlds"]["sgat"]["draws"]) == 2
    for w in res["worlds"].values():
        for d in w["draws"]:
            assert len(d["fitness"]) == 3 and all(0 <= p <= 1 for p in d["fall_rate"])
    assert res["worlds"]["sgat"]["draws"][0]["real_walks"] == 4
    assert 0 <= res["worlds"]["sgat"]["draws"][0]["real_walk_falls"] <= 4
    assert res["worlds"]["sgat"]["data_gaits"] == 1 and res["worlds"]["sim"]["data_gaits"] is None
    assert res["worlds"]["sim"]["draws"][0]["world_ceiling"] is None  # one deterministic episode
    # GAT is deterministic (its members averaged), so one episode per gait is its answer; SGAT samples
    from experiments.runtime.tasks import run_episode

    assert res["worlds"]["gat"]["episodes"] == 1 and res["worlds"]["sgat"]["episodes"] == 2
    assert res["worlds"]["gat"]["draws"][0]["world_ceiling"] is None
    panel = json.loads((out / "panel.json").read_text())["gaits"]
    for name, same in (("gat", True), ("sgat", False)):
        task = {"world": "grounded", "transformer": str(out / "models" / f"{parse_world(name).key}_d0"),
                "theta": panel[0]["theta"], "seconds": 1.5}
        a, b = (run_episode({**task, "seed": s}) for s in (1, 2))
        assert (a["distance_m"] == b["distance_m"]) is same, (name, a["distance_m"], b["distance_m"])
    # teacher forcing along each draw's grounding walks pulls the sim's legs toward the real ones
    for name in ("sgat", "gat"):
        for d in res["worlds"][name]["draws"]:
            rp = d["replay"]
            assert rp["walks"] == 4 and rp["real_fell"] == d["real_walk_falls"]
            assert rp["fell"] == rp["fell_with_real"] + rp["fell_without_real"] and rp["fell_with_real"] <= rp["real_fell"]
            assert 0 < rp["q_rms_rad"] < rp["q_rms_plain_rad"], rp
    assert "replay" not in res["worlds"]["sim"]["draws"][0]
    table = (out / "table.txt").read_text()
    forced = table.split("teacher-forced")[1].split("\n\n")[0].splitlines()[1:]
    assert sorted(line.split()[0] for line in forced) == ["gat", "sgat"]  # the grounded worlds only
    # fidelity against episodes per gait: SGAT at 1 and 2 episodes, GAT and the sim deterministic
    curve = table.split("against episodes per gait")[1].splitlines()[2:]
    assert [line.split()[:2] for line in curve] == [["sgat", "1"], ["sgat", "2"]]
    for f in ("fidelity.json", "fidelity.png", "fidelity_episodes.png", "table.txt", "panel.json", "episodes.jsonl"):
        assert (out / f).exists(), f
    n_lines = len((out / "episodes.jsonl").read_text().splitlines())
    # a second run with one more world measures only that world
    assert main([*args[:-5], "--worlds", "sim", "sgat", "gat", "ane", "--out", str(out), "--timings", "--json"]) == 0
    res2 = json.loads(capsys.readouterr().out)
    assert len((out / "episodes.jsonl").read_text().splitlines()) == n_lines + 3 * 2
    assert res2["worlds"]["sgat"] == res["worlds"]["sgat"]
    assert res2["wall_s"] > res["wall_s"] > 0  # the run's time accumulates over its invocations (timing.json)
    # ... and so does its split over the phases (phases.json): the first invocation ran them all
    from experiments.fidelity.run import PHASES

    ph, ph2 = res["phases_s"], res2["phases_s"]
    assert list(ph) == [p for p in PHASES if p not in ("excitation logs", "diagnoses", "servo fits", "walk fits")]  # no identified world here
    assert all(v > 0 for v in ph.values()) and sum(ph.values()) <= res["wall_s"]
    assert list(ph2) == list(ph) and all(ph2[k] >= ph[k] for k in ph) and ph2["world episodes"] > ph["world episodes"]
    assert ph2["teacher forcing"] == ph["teacher forcing"]  # resumed from replay.json: nothing teacher-forced again
    # other settings in the same directory are refused; another identification time budget is not
    assert main(["fidelity", *TINY[:-2], "--real-trials", "3", "--workers", "1", "--out", str(out)]) == 2
    assert "other settings" in capsys.readouterr().err
    assert main([*args[:-5], "--worlds", "sim", "--identify-budget", "30", "--out", str(out), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["worlds"]["sim"] == res["worlds"]["sim"]


def test_params_with_one_file_name_stay_apart(tmp_path, capsys):
    """Table I writes ``thetas/sgat_step1.json`` in every seed's directory: given together, each is
    its own gait (its own name and real trials), not the first one's cached results again."""
    from experiments.fidelity.run import param_gait_names
    from walk_engine import GaitParams

    th0 = GaitParams.initial()
    (tmp_path / "s0").mkdir(), (tmp_path / "s1").mkdir()
    a = th0.save(tmp_path / "s0" / "step1.json")
    b = GaitParams.from_vector(np.clip(th0.to_vector() + 0.3, 0, 1)).save(tmp_path / "s1" / "step1.json")
    assert param_gait_names([a, b]) == ["s0/step1", "s1/step1"]
    assert param_gait_names([a, str(tmp_path / "other.json")]) == ["step1", "other"]
    with pytest.raises(ValueError, match="twice"):
        param_gait_names([a, a])
    with pytest.raises(ValueError, match="clashes"):
        param_gait_names([str(tmp_path / "theta0.json")])
    out = tmp_path / "fid"
    assert main(["fidelity", "--gaits", "0", *TINY[2:], "--worlds", "sim", "--params", a, b, "--out", str(out),
                 "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["gaits"] == ["theta0", "s0/step1", "s1/step1"]
    real = [(f, p) for f, p in zip(res["real"]["fitness"], res["real"]["speed_cm_s"])]
    assert real[1] == real[0]  # the same gait on the same paired seeds
    assert real[2] != real[1]  # another gait: walked, not read back from the first file's cache
    # the given gaits scored apart from the drawn one (one file name: no group per name)
    assert [(r["group"], r["gaits"]) for r in res["groups"]] == [("drawn", 1), ("given", 2)]


def test_gait_groups_score_each_world_on_the_drawn_and_the_given_gaits_apart():
    """A world exact on the drawn gaits and 5 points optimistic on the optimized ones (given as θ
    files) shows no bias on the first group and +5 on the second, per file name too; it ranks the
    drawn gaits perfectly, and a world that rates the given gaits in reverse picks their worst."""
    from experiments.fidelity.run import GROUP_MIN_RANK, format_groups, gait_groups, group_rows

    drawn, per_name = GROUP_MIN_RANK, 3
    names = ["theta0"] + [f"box{i:02d}" for i in range(drawn - 1)]
    names += [f"s{k}/hybrid_step1" for k in range(per_name)] + [f"s{k}/hybrid_step2" for k in range(per_name)]
    G = len(names)
    real = np.arange(G, dtype=float)
    trials = np.repeat(real[:, None], 4, axis=1) + np.array([-1.0, 1.0, -1.0, 1.0])
    given = np.arange(drawn, G)
    exact_then_optimistic = real + np.where(np.arange(G) >= drawn, 5.0, 0.0)
    reversed_given = real.copy()
    reversed_given[given] = real[given][::-1]
    res = {"config": {"params": [f"s{k}.json" for k in range(2 * per_name)]}, "gaits": names,
           "real": {"fitness": real.tolist(), "fitness_trials": trials.tolist(), "fall_rate": [0.5] * G},
           "worlds": {w: {"draws": [{"fitness": f.tolist(), "fall_rate": [0.5] * G}]}
                      for w, f in (("optimistic", exact_then_optimistic), ("reversed", reversed_given))}}
    groups = gait_groups(res)
    assert groups["drawn"] == list(range(drawn)) and groups["given"] == given.tolist()
    assert groups["given: hybrid_step1"] == list(range(drawn, drawn + per_name))
    assert groups["given: hybrid_step2"] == list(range(drawn + per_name, G))
    rows = {(r["group"], r["world"]): r for r in group_rows(res)}
    assert rows[("drawn", "optimistic")]["bias"]["median"] == pytest.approx(0.0)
    assert rows[("drawn", "optimistic")]["rho"]["median"] == pytest.approx(1.0)
    assert rows[("drawn", "optimistic")]["pick_regret"]["median"] == pytest.approx(0.0)
    for g in ("given", "given: hybrid_step1", "given: hybrid_step2"):
        assert rows[(g, "optimistic")]["bias"]["median"] == pytest.approx(5.0)
    assert rows[("given", "optimistic")]["rho"] is None  # 6 gaits: too few to rank
    assert rows[("given", "reversed")]["pick_regret"]["median"] == pytest.approx(real[given].max() - real[given].min())
    assert rows[("given", "reversed")]["bias"]["median"] == pytest.approx(0.0)  # errors cancel in the bias,
    reversed_error = np.mean(np.abs(real[given][::-1] - real[given]))
    assert rows[("given", "reversed")]["mae"]["median"] == pytest.approx(reversed_error)  # not in the error
    assert rows[("given", "optimistic")]["mae"]["median"] == pytest.approx(5.0)
    assert rows[("given", "optimistic")]["real_fitness"] == pytest.approx(real[given].mean())
    assert rows[("given", "optimistic")]["real_fitness_se"] == pytest.approx(np.std([-1, 1, -1, 1], ddof=1) / 2)
    assert any("hybrid_step2" in line and "+5.0" in line for line in format_groups(res))
    assert gait_groups({**res, "config": {"params": []}}) == {} and group_rows({**res, "config": {}}) == []


def test_fidelity_bad_input(tmp_path, capsys):
    assert main(["fidelity", "--worlds", "sgat:nope=1", "--out", str(tmp_path / "x")]) == 2
    assert "unknown option" in capsys.readouterr().err
    assert main(["fidelity", "--params", str(tmp_path / "missing.json"), "--out", str(tmp_path / "x")]) == 2
    assert "no such file" in capsys.readouterr().err
    assert main(["fidelity", "--gaits", "-1", "--out", str(tmp_path / "x")]) == 2
    assert "gaits" in capsys.readouterr().err


T1 = ["--methods", "sgat,none", "--seeds", "2", "--trials", "3", "--popsize", "3", "--generations", "2",
      "--grounding-steps", "1", "--seconds", "0.8", "--workers", "1"]


def test_table1_resumes_after_sigkill(tmp_path):
    ref = tmp_path / "ref"
    assert main(["table1", *T1, "--out", str(ref), "--json"]) == 0
    a = json.loads((ref / "table1.json").read_text())
    assert [(r["method"], r["step"]) for r in a["rows"]] == [("theta0", 0), ("sgat", 1), ("none", 1)]
    assert a["rows"][1]["n"] == 2 * 3 and a["rows"][0]["n"] == 3
    assert {(t["a"], t["b"]) for t in a["tests"]} == {("sgat", "none"), ("sgat", "theta0"), ("none", "theta0")}
    # the per-trial record (for pairing a later run trial by trial) is what the rows pool
    tr = a["trials"]
    assert set(tr) == {"theta0", "sgat|1|0", "sgat|1|1", "none|1|0", "none|1|1"}
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
    while not (run / "opt_seed1" / "generations.csv").exists() and proc.poll() is None and time.time() - t0 < 300:
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
    assert {(t["method"], t["step"]) for t in c["baseline"]["tests"]} == {("sgat", 1), ("none", 1)}
    own = [t for t in c["baseline"]["tests"] if "baseline_method" not in t]
    assert len(own) == 2 and all(t["fitness"]["mean_diff"] == 0 and t["falls"]["only_a"] == t["falls"]["only_b"] == 0
                                 for t in own)
    # ... and SGAT against the baseline's NONE, as a run tests them (comparisons): the within-run test again
    cross, = [t for t in c["baseline"]["tests"] if "baseline_method" in t]
    within, = [t for t in a["tests"] if (t["a"], t["b"]) == ("sgat", "none")]
    assert (cross["method"], cross["baseline_method"]) == ("sgat", "none")
    assert cross["fitness"]["mean_diff"] == pytest.approx(within["fitness"]["mean_diff"], abs=1e-3)  # trials kept to 4 decimals
    assert cross["per_seed_diff"] == pytest.approx(within["per_seed_diff"], abs=1e-3)


def test_table1_grows_by_methods_without_redoing_anything(tmp_path):
    """More methods given to a finished Table I run: every seed's optimization run gains them (its real
    grounding walks reused), only the new gaits walk the real trials, the old rows stay as they were,
    and a noise-enveloped method is tested against its base method and against ANE."""
    from experiments.table1.run import comparisons

    assert comparisons(("sgat", "gat", "ane", "sgat+ane", "hybrid+ane")) == [  # only pairs of methods run: no hybrid
        ("sgat", "gat"), ("sgat+ane", "sgat"), ("sgat+ane", "ane"), ("hybrid+ane", "ane")]
    # hybrid against the identified sim it grounds: what the learned grounding adds to the identified physics
    assert comparisons(("identified", "hybrid", "sgat")) == [("hybrid", "sgat"), ("hybrid", "identified")]
    args = ["--seeds", "1", "--trials", "3", "--popsize", "3", "--generations", "2", "--grounding-steps", "1",
            "--seconds", "0.8", "--workers", "1"]
    run = tmp_path / "t1"
    assert main(["table1", "--methods", "sgat,ane", *args, "--out", str(run), "--json"]) == 0
    a = json.loads((run / "table1.json").read_text())
    walked = (run / "episodes.jsonl").read_text().splitlines()
    real = sorted(p.name for p in (run / "opt_seed0" / "data").glob("real_*"))
    assert main(["table1", "--methods", "sgat,ane,sgat+ane", *args, "--out", str(run), "--json"]) == 0
    b = json.loads((run / "table1.json").read_text())
    assert b["rows"][:3] == a["rows"] and b["rows"][3]["method"] == "sgat+ane" and b["rows"][3]["n"] == 3
    now = (run / "episodes.jsonl").read_text().splitlines()
    assert now[:len(walked)] == walked and len(now) == len(walked) + 3  # 3 trials of the one new gait
    assert all(json.loads(x)["key"].startswith("sgat+ane|1|0|t") for x in now[len(walked):])
    assert sorted(p.name for p in (run / "opt_seed0" / "data").glob("real_*")) == real
    assert {(t["a"], t["b"]) for t in b["tests"]} - {(t["a"], t["b"]) for t in a["tests"]} == {
        ("sgat+ane", "sgat"), ("sgat+ane", "ane"), ("sgat+ane", "theta0")}


def test_table1_pairs_a_run_with_a_baseline_run(tmp_path, capsys):
    """compare_runs pairs (method, step, seed) gaits trial by trial: a run whose every trial is 1 point
    fitter than the baseline's and falls once less shows exactly that; runs on other trials are refused."""
    from experiments.table1.run import Table1Config, baseline_verdict, compare_runs, load_baseline

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
                     for i, m in enumerate(("ane", "sgat+ane")) for s in range(2)}}
    r2 = {"theta0": base["theta0"], **{f"sgat+ane|1|{s}": {"fitness": [5.0 + s] * 10, "fell": [0] * 10} for s in range(2)}}
    got = {t.get("baseline_method", t["method"]): t for t in compare_runs({"trials": r2}, {"trials": b2})}
    assert set(got) == {"sgat+ane", "sgat", "ane"} and got["sgat+ane"]["method"] == "sgat+ane"
    assert got["ane"]["per_seed_diff"] == [5.0, 5.0] and got["sgat+ane"]["per_seed_diff"] == [4.0, 4.0]
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


def test_a_world_s_own_episode_noise_caps_its_ceiling(tmp_path):
    """``world_ceiling``: the split-half ceiling of a stochastic world's own episodes. A world whose
    episodes differ only by small noise around each gait's value gets a ceiling near 1; one whose
    episode noise swamps the gaits' differences gets a low one; the deterministic sim gets none."""
    from experiments.fidelity.run import Fidelity, format_table

    cfg = FidelityConfig(worlds=("sim", "ane", "ane:sigma=0.1"), gaits=11, real_trials=6, episodes=8, bootstrap=50)
    run = Fidelity(cfg, str(tmp_path), executor=None)
    gaits = [{"name": f"g{i}"} for i in range(12)]
    true = np.linspace(-10, 10, 12)
    rng = np.random.default_rng(0)
    eps = {}
    for g, v in zip(gaits, true):
        for j in range(6):
            eps[f"real|{g['name']}|t{j}"] = {"fitness": v + rng.normal(0, 1), "fell": False, "speed_cm_s": 1.0}
        eps[f"w|{run.specs[0].key}|d0|{g['name']}|e0"] = {"fitness": v, "fell": False, "speed_cm_s": 1.0}
        for spec, noise in zip(run.specs[1:], (0.5, 40.0)):
            for j in range(8):
                eps[f"w|{spec.key}|d0|{g['name']}|e{j}"] = {"fitness": v + rng.normal(0, noise), "fell": j % 2 == 0,
                                                            "speed_cm_s": 1.0}
    run._episodes = eps
    info = {"real_walks": 0, "real_seconds": 0.0, "excitation_logs": 0, "excitation_seconds": 0.0}
    res = run.result(gaits, {s.name: [info] for s in run.specs})
    quiet, loud = res["worlds"]["ane"]["draws"][0], res["worlds"]["ane:sigma=0.1"]["draws"][0]
    assert quiet["world_ceiling"] > 0.95 and loud["world_ceiling"] < 0.7
    assert res["worlds"]["sim"]["draws"][0]["world_ceiling"] is None
    assert "world_ceiling" not in res["worlds"]["sim"]["summary"]
    assert res["worlds"]["ane"]["summary"]["world_ceiling"]["min"] == quiet["world_ceiling"]
    table = format_table(res)
    assert "own-noise ceiling" in table and f"{quiet['world_ceiling']:.2f}" in table
    # the paired test of the rankings: every world against the sim, the variant against its plain kind;
    # the loud world ranks worse than the quiet one beyond the noise, the quiet one as well as the sim
    # (which is the truth here), and the observed figure is the difference of the draws' rho
    assert np.array(quiet["fitness_episodes"]).shape == (12, 8) and np.array(res["real"]["fitness_trials"]).shape == (12, 6)
    pairs = {(r["world"], r["reference"]): r for r in res["paired"]}
    assert list(pairs) == [("ane", "sim"), ("ane:sigma=0.1", "sim"), ("ane:sigma=0.1", "ane")]
    worse = pairs[("ane:sigma=0.1", "ane")]
    assert worse["diff"] == pytest.approx(loud["rho"] - quiet["rho"]) and worse["ci"][1] < 0 and worse["p_value"] < 0.05
    assert worse["ci_panel"][1] < 0 and worse["p_value_panel"] < 0.05  # the panel's gaits kept
    tie = pairs[("ane", "sim")]
    assert abs(tie["diff"]) < 0.05 and tie["ci"][0] <= 0 and tie["p_value"] > 0.05
    assert "paired differences of rho" in table and "ane:sigma=0.1 - ane" in table


def test_the_oracle_world_walks_the_real_world_on_fresh_seeds_per_draw(tmp_path):
    """``oracle``: real episodes, on seeds that are neither the real trials' nor another draw's, and
    the same seeds for every gait of a draw (paired like every training world)."""
    from experiments.fidelity.run import Fidelity

    assert parse_world("oracle").per_draw and "oracle" not in FidelityConfig().worlds
    with pytest.raises(ValueError, match="unknown option"):
        parse_world("oracle:alpha=0.5")
    cfg = FidelityConfig(worlds=("sim", "oracle"), gaits=2, real_trials=3, episodes=3, data_seeds=2)
    run = Fidelity(cfg, str(tmp_path), executor=None)
    oracle = run.specs[1]
    gaits = [{"name": "a", "theta": [0.0]}, {"name": "b", "theta": [1.0]}]
    d0, d1 = (run._world_tasks(oracle, d, {}, gaits) for d in (0, 1))
    assert {t["world"] for t in d0 + d1} == {"real"} and len(d0) == 2 * 3
    seeds0 = [t["seed"] for t in d0 if t["theta"] == [0.0]]
    assert seeds0 == [t["seed"] for t in d0 if t["theta"] == [1.0]]
    assert not set(seeds0) & {t["seed"] for t in d1}
    sim_seeds = {t["seed"] for t in run._world_tasks(run.specs[0], 0, {}, gaits)}
    assert not set(seeds0) & sim_seeds
    from experiments.fidelity.run import _REAL, _seeds

    assert not set(seeds0) & set(_seeds(cfg.seed, _REAL, n=cfg.real_trials))  # not the real trials' seeds


def test_a_noise_enveloped_world_adds_the_ane_noise_to_its_episodes_only(tmp_path):
    """``sgat:ane=0.05`` (``optimize --methods sgat+ane``): the world's episodes carry the noise, its
    grounding is SGAT's; a GAT world with it is no longer deterministic; the plain worlds keep their
    cache keys (the option hashes only when set)."""
    from experiments.fidelity.run import Fidelity

    w, g = parse_world("sgat:ane=0.05"), parse_world("gat:ane=0.03")
    assert (w.envelope, w.grounding, w.kind) == (0.05, parse_world("sgat").grounding, "sgat")
    assert parse_world("gat").deterministic and not g.deterministic and parse_world("hybrid:ane=0.05").envelope == 0.05
    assert parse_world("sgat:ane=0").key == parse_world("sgat").key == "sgat-5b13614641" != w.key
    for bad, words in [("sim:ane=0.05", "unknown option"), ("ane:ane=0.05", "unknown option"), ("sgat:ane=-1", "bad value"),
                       ("identified:ane=x", "bad value")]:
        with pytest.raises(ValueError, match=words):
            parse_world(bad)
    cfg = FidelityConfig(worlds=("sgat", "sgat:ane=0.05", "gat:ane=0.03"), gaits=2, real_trials=2, episodes=3)
    run = Fidelity(cfg, str(tmp_path), executor=None)
    gaits = [{"name": "a", "theta": [0.0]}, {"name": "b", "theta": [1.0]}]
    plain, noisy, gat = (run._world_tasks(s, 0, {"transformer": "m"}, gaits) for s in run.specs)
    assert all("action_noise" not in t for t in plain) and {t["action_noise"] for t in noisy} == {0.05}
    assert [t["seed"] for t in plain] == [t["seed"] for t in noisy]  # the same episode seeds: paired
    assert len(gat) == 2 * 3 and {t["action_noise"] for t in gat} == {0.03}  # every episode, not one per gait


def test_the_mean_oracle_walks_the_real_world_at_the_middle_of_every_effect_range(tmp_path):
    """``oracle:mean=1``: the real world's episodes on the oracle's own seeds, with every effect fixed
    at the middle of its range (``experiments.runtime.tasks.mean_profile``): an episode draws exactly those
    values, whatever its seed, while the plain real world draws others."""
    from envs.effects import EFFECTS, PROFILES
    from experiments.fidelity.run import Fidelity
    from experiments.runtime.tasks import _real_profile, _world, mean_profile

    m = parse_world("oracle:mean=1")
    assert m.oracle_mean and not parse_world("oracle").oracle_mean and m.key != parse_world("oracle").key
    mp = mean_profile(PROFILES["real"])
    assert mp.name == "real:mean" and mp.latency_s == (0.015, 0.015) and mp.terrain_amplitude == (0.01, 0.01)
    assert all(lo == hi for lo, hi in (getattr(mp, f) for f in EFFECTS))
    assert _real_profile("real", None) == "real"
    with pytest.raises(ValueError, match="NAME:mean"):
        _real_profile("real:median", None)
    cfg = FidelityConfig(worlds=("oracle", "oracle:mean=1"), gaits=2, real_trials=2, episodes=2, data_seeds=1)
    run = Fidelity(cfg, str(tmp_path), executor=None)
    gaits = [{"name": "a", "theta": [0.0]}, {"name": "b", "theta": [1.0]}]
    plain, mean = (run._world_tasks(s, 0, {}, gaits) for s in run.specs)
    assert [t["seed"] for t in plain] == [t["seed"] for t in mean]  # paired: only the physics differs
    assert {t["profile"] for t in mean} == {"real:mean"} and {t["profile"] for t in plain} == {"real"}
    env = _world({"world": "real", "profile": "real:mean", "seed": 0})
    for seed in (1, 2):
        env.reset(seed=seed)
        e = env.unwrapped.effects
        assert e.latency_s == pytest.approx(0.015) and e.terrain_amplitude == pytest.approx(0.01)
        assert np.allclose(e.kp_scale, 0.925) and np.allclose(e.foot_friction, 0.7)
    real = _world({"world": "real", "profile": "real", "seed": 0})
    real.reset(seed=1)
    assert not np.allclose(real.unwrapped.effects.kp_scale, 0.925)


def test_the_mean_oracle_in_mujoco_builds_the_mean_physics_into_the_identified_sim(tmp_path):
    """``oracle:mean=1:engine=mujoco``: the real world's mean physics as a diagnosis report
    (``experiments.runtime.tasks.mean_physics_report``), walked in the identified sim on the oracle's seeds;
    the sim's model carries every value (latency in the actuator delay, the weaker servos and torque
    limits in the actuators, the heavier links) and its ground is as rough as the lumpy terrain."""
    from experiments.fidelity.run import Fidelity
    from experiments.runtime.tasks import _world, mean_physics_report
    from robots import get_robot
    from terrain import lumpy

    m = parse_world("oracle:mean=1:engine=mujoco")
    assert m.oracle_engine == "mujoco" and m.key != parse_world("oracle:mean=1").key
    assert parse_world("oracle:mean=1:engine=pybullet").key == parse_world("oracle:mean=1").key
    for bad, msg in (("oracle:engine=mujoco", "needs mean=1"), ("oracle:mean=1:engine=ode", "pybullet or mujoco")):
        with pytest.raises(ValueError, match=msg):
            parse_world(bad)
    rep = mean_physics_report("real")
    robot = get_robot("nao")
    assert rep["model"]["latency"] == pytest.approx(0.015) and rep["model"]["torque_limit"] == pytest.approx(0.825)
    assert all(rep["model"][f"pd_gain[{j}]"] == pytest.approx(0.925) for j in robot.actuated_joint_names)
    rms = rep["effects"][0]["value"]
    assert rep["effects"][0]["family"] == "terrain_roughness"
    assert rms == pytest.approx(np.std(lumpy(99, amplitude=0.01).heights), rel=0.25) and 0.001 < rms < 0.005

    cfg = FidelityConfig(worlds=("oracle:mean=1", "oracle:mean=1:engine=mujoco"), gaits=2, real_trials=2,
                         episodes=2, data_seeds=1)
    run = Fidelity(cfg, str(tmp_path), executor=None)
    gaits = [{"name": "a", "theta": [0.0]}]
    bullet, sim = (run._world_tasks(s, 0, {}, gaits) for s in run.specs)
    assert [t["seed"] for t in bullet] == [t["seed"] for t in sim]  # paired: only the engine differs
    assert {t["world"] for t in sim} == {"identified"} and all("profile" not in t for t in sim)
    env = _world(sim[0]).unwrapped
    plain = _world({"world": "sim", "seed": 0}).unwrapped
    assert np.allclose(env.model.actuator_delay, 0.015)
    ratio = env.model.actuator_forcerange[:, 1] / plain.model.actuator_forcerange[:, 1]
    assert np.allclose(ratio, 0.825)
    assert env.model.body_mass.sum() == pytest.approx(1.015 * plain.model.body_mass.sum(), rel=1e-3)
    env.reset(seed=3)
    assert np.std(env.terrain.heights) == pytest.approx(rms, rel=0.05)


def test_the_mean_oracles_swap_grounds_across_the_engines_on_the_same_surfaces(tmp_path):
    """``ground=real`` walks the MuJoCo mean-physics oracle on the real world's own lumpy terrain and
    ``ground=model`` the PyBullet one on the identified sim's Gaussian surface: episode for episode
    (the oracle's seeds, shared by the four worlds) the very heightfield the other engine walks, so
    that the 2 x 2 of engine and ground differ in one thing at a time."""
    from experiments.fidelity.run import Fidelity
    from experiments.runtime.tasks import _world

    assert parse_world("oracle:mean=1:ground=real").key == parse_world("oracle:mean=1").key  # PyBullet's own ground
    assert parse_world("oracle:mean=1:engine=mujoco:ground=model").key == parse_world("oracle:mean=1:engine=mujoco").key
    assert parse_world("oracle:mean=1:ground=model").key != parse_world("oracle:mean=1").key
    for bad, msg in (("oracle:ground=model", "needs mean=1"), ("oracle:mean=1:ground=gravel", "real or model")):
        with pytest.raises(ValueError, match=msg):
            parse_world(bad)
    worlds = ("oracle:mean=1", "oracle:mean=1:ground=model", "oracle:mean=1:engine=mujoco",
              "oracle:mean=1:engine=mujoco:ground=real")
    run = Fidelity(FidelityConfig(worlds=worlds, gaits=2, real_trials=2, episodes=2, data_seeds=1), str(tmp_path),
                   executor=None)
    gaits = [{"name": "a", "theta": [0.0]}]
    pb_real, pb_model, mj_model, mj_real = (run._world_tasks(s, 0, {}, gaits) for s in run.specs)
    assert len({tuple(t["seed"] for t in ts) for ts in (pb_real, pb_model, mj_model, mj_real)}) == 1
    assert [t["world"] for t in (pb_real[0], pb_model[0], mj_model[0], mj_real[0])] == ["real", "real", "identified",
                                                                                       "identified"]
    seed = pb_real[0]["seed"]

    def ground(task):
        env = _world(task).unwrapped
        env.reset(seed=seed)
        return env.terrain.heights

    lumpy_pb, lumpy_mj, gauss_mj, gauss_pb = (ground(t[0]) for t in (pb_real, mj_real, mj_model, pb_model))
    assert np.array_equal(lumpy_pb, lumpy_mj) and np.array_equal(gauss_mj, gauss_pb)
    assert not np.allclose(lumpy_pb, gauss_mj, atol=1e-4)
    # the lumpy terrain of the mean profile (its 1 cm peak), and the surface of the report's RMS height
    assert np.abs(lumpy_pb).max() == pytest.approx(0.01)
    assert np.std(gauss_mj) == pytest.approx(run._mean_ground_level("model"), rel=0.05)
    with pytest.raises(ValueError, match="real or model"):
        _world({**pb_real[0], "ground": ["gravel", 0.01]})


def test_the_rebuilt_mujoco_oracle_walks_the_identified_contact_without_play_hinges(tmp_path):
    """``oracle:mean=1:engine=mujoco:compliance=0.004:backlash=0``: the MuJoCo form of the mean physics
    with the ground contact the diagnosis identifies and no backlash terms, from a report of its own
    beside the plain yardstick's (same seeds, same ground); the plain form's key and model are unchanged;
    the options belong to the MuJoCo form only and take a time constant > 0."""
    from experiments.fidelity.run import Fidelity
    from tools.readme import _mujoco_form
    from experiments.runtime.tasks import _world, mean_physics_report

    plain = parse_world("oracle:mean=1:engine=mujoco")
    assert parse_world("oracle:mean=1:engine=mujoco:backlash=1").key == plain.key
    rebuilt = parse_world("oracle:mean=1:engine=mujoco:compliance=0.004:backlash=0")
    assert (rebuilt.oracle_compliance, rebuilt.oracle_backlash) == (0.004, False) and rebuilt.key != plain.key
    for bad, msg in (("oracle:mean=1:compliance=0.004", "need mean=1:engine=mujoco"),
                     ("oracle:backlash=0", "need mean=1:engine=mujoco"),
                     ("oracle:mean=1:engine=mujoco:compliance=0", "bad value for compliance"),
                     ("oracle:mean=1:engine=mujoco:compliance=inf", "bad value for compliance"),
                     ("sgat:backlash=0", "unknown option")):
        with pytest.raises(ValueError, match=msg):
            parse_world(bad)
    with pytest.raises(ValueError, match="time constant"):
        mean_physics_report("real", ground_compliance=-0.004)
    ablated = parse_world("oracle:mean=1:engine=mujoco:drop=torque_limit+pd_gain+pd_gain")
    assert ablated.oracle_drop == "pd_gain+torque_limit"  # sorted, once each: one world, one key
    assert ablated.key == parse_world("oracle:mean=1:engine=mujoco:drop=pd_gain+torque_limit").key != plain.key
    for bad in ("oracle:mean=1:engine=mujoco:drop=backlash", "oracle:mean=1:engine=mujoco:drop=gravity"):
        with pytest.raises(ValueError, match="unknown option value drop"):
            parse_world(bad)
    with pytest.raises(ValueError, match="unknown effect famil"):
        mean_physics_report("real", drop=["gravity"])
    flat = mean_physics_report("real", drop=["pd_gain", "terrain_roughness"])
    full = mean_physics_report("real")
    assert flat["effects"] == [] and not any(k.startswith("pd_gain[") for k in flat["model"])
    assert {k: v for k, v in full["model"].items() if not k.startswith("pd_gain[")} == flat["model"]

    run = Fidelity(FidelityConfig(worlds=(plain.name, rebuilt.name), gaits=2, real_trials=2, episodes=2, data_seeds=1),
                   str(tmp_path), executor=None)
    gaits = [{"name": "a", "theta": [0.0]}]
    old, new = (run._world_tasks(s, 0, {}, gaits) for s in run.specs)
    assert [t["seed"] for t in old] == [t["seed"] for t in new] and old[0]["identified"] != new[0]["identified"]
    reports = [json.loads(open(t[0]["identified"][0]).read()) for t in (old, new)]
    assert reports[0] == mean_physics_report("real")  # the yardstick's report as before
    assert {k for k in reports[0]["model"] if not k.startswith("backlash[")} | {"ground_compliance"} == set(reports[1]["model"])
    seed = old[0]["seed"]
    envs = [_world(t[0]).unwrapped for t in (old, new)]
    for env in envs:
        env.reset(seed=seed)
    hinges = [[e.model.joint(j).name for j in range(e.model.njnt) if e.model.joint(j).name.endswith("__play")] for e in envs]
    assert len(hinges[0]) >= 20 and hinges[1] == []
    assert np.allclose(envs[0].model.geom_solref[:, 0], 0.01) and np.allclose(envs[1].model.geom_solref[:, 0], 0.004)
    assert np.array_equal(envs[0].terrain.heights, envs[1].terrain.heights)  # the same Gaussian surface
    assert _mujoco_form({"oracle_compliance": 0.004, "oracle_backlash": False}) == \
        " with a ground contact of 4 ms and no backlash terms"
    assert _mujoco_form({"oracle_engine": "mujoco"}) == ""
    assert _mujoco_form({"oracle_backlash": False, "oracle_drop": ["pd_gain", "torque_limit"]}) == \
        " with no backlash terms, without pd gain, torque limit"


def test_worlds_one_setting_apart_are_paired():
    """Beside the fixed pairs, any two worlds of one kind that differ in one setting are tested against
    each other: the four mean-physics oracles edge by edge (engine on each ground, ground in each
    engine), a variant against the variant with one option fewer; never worlds two settings apart."""
    from experiments.fidelity.run import world_pairs

    oracles = ["oracle:mean=1", "oracle:mean=1:ground=model", "oracle:mean=1:engine=mujoco",
               "oracle:mean=1:engine=mujoco:ground=real"]
    pairs = world_pairs(oracles, {n: "oracle" for n in oracles})
    assert sorted(pairs) == sorted([(oracles[1], oracles[0]), (oracles[2], oracles[1]), (oracles[3], oracles[0]),
                                    (oracles[3], oracles[2])])
    names = ["sim", "hybrid", "hybrid:alpha=0.3", "hybrid:alpha=0.3:delay=auto", "sgat:alpha=0.3"]
    pairs = world_pairs(names, {n: n.split(":")[0] for n in names})
    assert ("hybrid:alpha=0.3:delay=auto", "hybrid:alpha=0.3") in pairs
    assert ("hybrid:alpha=0.3:delay=auto", "hybrid") in pairs  # a variant against its plain kind, as before
    assert ("sgat:alpha=0.3", "hybrid:alpha=0.3") not in pairs  # another kind
    assert world_pairs(["sim", "old:name=1"], {}) == [("old:name=1", "sim")]  # unparsable: the fixed rules only
    rebuilt = ["oracle:mean=1", "oracle:mean=1:engine=mujoco", "oracle:mean=1:engine=mujoco:backlash=0",
               "oracle:mean=1:engine=mujoco:compliance=0.004:backlash=0"]
    pairs = world_pairs(rebuilt, {n: "oracle" for n in rebuilt})
    assert (rebuilt[2], rebuilt[1]) in pairs and (rebuilt[3], rebuilt[2]) in pairs  # one setting apart
    assert (rebuilt[2], rebuilt[0]) in pairs and (rebuilt[3], rebuilt[0]) in pairs  # a rebuilt form against PyBullet's
    assert (rebuilt[1], rebuilt[0]) not in pairs and (rebuilt[3], rebuilt[1]) not in pairs  # two settings apart
    r = rebuilt[3]
    drops = [r, f"{r}:drop=latency", f"{r}:drop=pd_gain", f"{r}:drop=latency+pd_gain"]
    pairs = world_pairs(drops, {n: "oracle" for n in drops})
    assert {(drops[1], r), (drops[2], r), (drops[3], drops[1]), (drops[3], drops[2])} <= set(pairs)
    assert (drops[2], drops[1]) not in pairs  # ablations of other families: not compared
    names = ["sim", "ane", "gat", "sgat", "identified", "hybrid:alpha=0.3", "oracle:mean=1", "oracle"]
    pairs = world_pairs(names, {n: n.split(":")[0] for n in names})
    against_real = [a for a, b in pairs if b == "oracle"]
    assert sorted(against_real) == sorted(["ane", "gat", "sgat", "identified", "hybrid:alpha=0.3", "oracle:mean=1"])
    assert ("oracle", "sim") in pairs and ("sim", "oracle") not in pairs  # the mean physics: as its variant
    assert not any(b == "oracle" for _, b in world_pairs(names[:-1], {n: n.split(":")[0] for n in names[:-1]}))


def test_a_run_without_a_terminal_reports_progress_within_a_chunk(tmp_path, monkeypatch):
    """Episodes are saved in chunks of 150; without a terminal the count and an ETA still go out as the
    executor's batches end, so 160 real trials (one chunk and a bit, minutes long) show their progress."""
    import experiments.runtime.batch
    import experiments.runtime.rundir
    from experiments.runtime.rundir import EpisodeLog

    def fake_map(ex, tasks, progress=None):
        for _ in tasks:
            progress(1)
        return [{"fitness": 1.0, "speed_cm_s": 1.0, "fell": False, "steps": 750} for _ in tasks]

    monkeypatch.setattr(experiments.runtime.batch, "map_episodes", fake_map)
    monkeypatch.setattr(experiments.runtime.rundir, "ETA_EVERY_S", -1.0)  # a line at every batch
    lines: list[str] = []
    log = EpisodeLog(str(tmp_path), {}, "run", say=lines.append)
    log.run(None, [{"key": f"k{i}"} for i in range(160)], "real trials", progress=False)
    counts = [ln for ln in lines if "ETA" in ln]
    assert counts[0].startswith("real trials: 1/160, ETA ") and counts[-1].startswith("real trials: 159/160, ETA ")
    assert len(counts) == 159  # every batch but the last, which ends the run
    assert lines[-1].startswith("real trials: done in") and len(log.done) == 160
