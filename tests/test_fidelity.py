"""sgatwalk fidelity: a tiny end-to-end run with resume, its scores and pairs, the worlds it walks, bad input."""

import json
import types

import numpy as np
import pytest

from experiments.cli import main
from experiments.fidelity.config import FidelityConfig
from experiments.fidelity.scoring import episode_counts, episodes_rows, episodes_view, summary
from experiments.runtime.worlds import parse_world

TINY = ["--gaits", "2", "--real-trials", "2", "--data-seeds", "2", "--episodes", "2", "--seconds", "1.5",
        "--workers", "1"]


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
    measured with fewer left out."""
    assert episode_counts(1) == [] and episode_counts(2) == [1, 2] and episode_counts(6) == [1, 2, 4, 6]
    assert episode_counts(16) == [1, 2, 4, 8, 16]

    def world(kind, rhos, bias, brier=0.2):
        draws = [{"draw": i, "rho": r, "bias": b, "mae": abs(b), "brier": brier, "pick_regret": 0.0}
                 for i, (r, b) in enumerate(zip(rhos, bias))]
        return {"kind": kind, "draws": draws, "summary": summary(draws)}

    # a world whose ranking and bias settle with more episodes: 0.5 worst at one, 0.9 at four
    noisy = {**world("sgat", [0.9, 0.92], [1.0, 1.5]), "episodes": 4,
             "by_episodes": {"1": world("sgat", [0.5, 0.7], [-3.0, 3.0]), "4": world("sgat", [0.9, 0.92], [1.0, 1.5])}}
    res = {"gaits": ["a", "b", "c"], "real": {"ceiling": 0.95, "trials": 10}, "worlds": {
        "sim": {**world("sim", [0.6], [5.0], brier=0.5), "episodes": 1, "deterministic": True},
        "gat": {**world("gat", [0.6, 0.6], [2.0, 2.0], brier=0.3), "episodes": 1, "deterministic": True},
        "sgat": noisy, "ane": {**world("ane", [0.3], [0.0]), "episodes": 2}}}
    one = episodes_view(res, 1)
    assert set(one["worlds"]) == {"sim", "gat", "sgat"} and one["worlds"]["sim"] is res["worlds"]["sim"]
    assert one["worlds"]["sgat"]["summary"]["rho"]["min"] == 0.5 and one["worlds"]["sgat"]["episodes"] == 1
    assert set(episodes_view(res, 2)["worlds"]) == {"sim", "gat", "ane"}  # ane ran 2 episodes and has no curve
    rows = {r["episodes"]: r for r in episodes_rows(res) if r["world"] == "sgat"}
    assert (rows[1]["rho_worst"], rows[4]["rho_worst"]) == (0.5, 0.9)
    assert rows[1]["bias_spread"] == pytest.approx(6.0) and rows[4]["bias_spread"] == pytest.approx(0.5)
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
    assert res["worlds"]["sim"]["draws"][0]["world_ceiling"] is None  # one deterministic episode
    # GAT is deterministic (its members averaged), so one episode per gait is its answer; SGAT samples
    from experiments.runtime.tasks import EpisodeTask, run_episode

    assert res["worlds"]["gat"]["episodes"] == 1 and res["worlds"]["sgat"]["episodes"] == 2
    assert res["worlds"]["gat"]["draws"][0]["world_ceiling"] is None
    panel = json.loads((out / "panel.json").read_text())["gaits"]
    for name, same in (("gat", True), ("sgat", False)):
        task = EpisodeTask("sim", panel[0]["theta"], 0, 1.5, transformer=str(out / "models" / f"{parse_world(name).key}_d0"))
        a, b = (run_episode(task.replace(seed=s)) for s in (1, 2))
        assert (a.distance_m == b.distance_m) is same, (name, a.distance_m, b.distance_m)
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
    from experiments.fidelity.config import PHASES

    ph, ph2 = res["phases_s"], res2["phases_s"]
    assert list(ph) == [p for p in PHASES if p not in ("excitation logs", "diagnoses")]  # no identified world here
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
    from experiments.fidelity.config import param_gait_names
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
    from experiments.fidelity.report import format_groups
    from experiments.fidelity.scoring import GROUP_MIN_RANK, gait_groups, group_rows

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
    assert "sgat has no option 'nope'" in capsys.readouterr().err
    assert main(["fidelity", "--worlds", "sgat", "sgat:alpha=0.5", "--out", str(tmp_path / "x")]) == 2
    assert "a world given twice" in capsys.readouterr().err
    assert main(["fidelity", "--params", str(tmp_path / "missing.json"), "--out", str(tmp_path / "x")]) == 2
    assert "no such file" in capsys.readouterr().err
    assert main(["fidelity", "--gaits", "-1", "--out", str(tmp_path / "x")]) == 2
    assert "gaits" in capsys.readouterr().err


def test_a_world_s_own_episode_noise_caps_its_ceiling(tmp_path):
    """``world_ceiling``: the split-half ceiling of a stochastic world's own episodes. A world whose
    episodes differ only by small noise around each gait's value gets a ceiling near 1; one whose
    episode noise swamps the gaits' differences gets a low one; the deterministic sim gets none."""
    from experiments.fidelity.report import format_table
    from experiments.fidelity.run import Fidelity

    cfg = FidelityConfig(worlds=("sim", "ane", "ane:ane=0.1"), gaits=11, real_trials=6, episodes=8, bootstrap=50)
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
    run._log = types.SimpleNamespace(done=eps)
    info = {"real_walks": 0, "real_seconds": 0.0, "excitation_logs": 0, "excitation_seconds": 0.0}
    res = run.result(gaits, {s.name: [info] for s in run.specs})
    quiet, loud = res["worlds"]["ane"]["draws"][0], res["worlds"]["ane:ane=0.1"]["draws"][0]
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
    assert list(pairs) == [("ane", "sim"), ("ane:ane=0.1", "sim"), ("ane:ane=0.1", "ane")]
    worse = pairs[("ane:ane=0.1", "ane")]
    assert worse["diff"] == pytest.approx(loud["rho"] - quiet["rho"]) and worse["ci"][1] < 0 and worse["p_value"] < 0.05
    assert worse["ci_panel"][1] < 0 and worse["p_value_panel"] < 0.05  # the panel's gaits kept
    tie = pairs[("ane", "sim")]
    assert abs(tie["diff"]) < 0.05 and tie["ci"][0] <= 0 and tie["p_value"] > 0.05
    assert "paired differences of rho" in table and "ane:ane=0.1 - ane" in table


def test_the_real_world_as_a_training_world_walks_fresh_seeds_per_draw(tmp_path):
    """``real``: real episodes, on seeds that are neither the real trials' nor another draw's, and
    the same seeds for every gait of a draw (paired like every training world)."""
    from experiments.fidelity.config import REAL
    from experiments.fidelity.run import Fidelity
    from experiments.runtime.seeds import derive_seeds

    assert parse_world("real").per_draw and "real" not in FidelityConfig().worlds
    cfg = FidelityConfig(worlds=("sim", "real"), gaits=2, real_trials=3, episodes=3, data_seeds=2)
    run = Fidelity(cfg, str(tmp_path), executor=None)
    real = run.specs[1]
    gaits = [{"name": "a", "theta": [0.0]}, {"name": "b", "theta": [1.0]}]
    none = {"transformer": None, "identified": None}
    d0, d1 = (run.world_tasks(real, d, none, gaits) for d in (0, 1))
    assert {t.world for t in d0 + d1} == {"real"} and len(d0) == 2 * 3
    seeds0 = [t.seed for t in d0 if t.theta == (0.0,)]
    assert seeds0 == [t.seed for t in d0 if t.theta == (1.0,)]
    assert not set(seeds0) & {t.seed for t in d1}
    sim_seeds = {t.seed for t in run.world_tasks(run.specs[0], 0, none, gaits)}
    assert not set(seeds0) & sim_seeds
    assert not set(seeds0) & set(derive_seeds(cfg.seed, REAL, n=cfg.real_trials))  # not the real trials' seeds


def test_a_noise_enveloped_world_adds_the_ane_noise_to_its_episodes_only(tmp_path):
    """``sgat:ane=0.05``: the world's episodes carry the noise, its grounding is SGAT's; a GAT world
    with it is no longer deterministic."""
    from experiments.fidelity.run import Fidelity

    w, g = parse_world("sgat:ane=0.05"), parse_world("gat:ane=0.03")
    assert (w.noise, w.grounding_config(), w.kind) == (0.05, parse_world("sgat").grounding_config(), "sgat")
    assert parse_world("gat").deterministic and not g.deterministic and parse_world("hybrid:ane=0.05").noise == 0.05
    assert parse_world("sgat:ane=0").key == parse_world("sgat").key != w.key
    cfg = FidelityConfig(worlds=("sgat", "sgat:ane=0.05", "gat:ane=0.03"), gaits=2, real_trials=2, episodes=3)
    run = Fidelity(cfg, str(tmp_path), executor=None)
    gaits = [{"name": "a", "theta": [0.0]}, {"name": "b", "theta": [1.0]}]
    plain, noisy, gat = (run.world_tasks(s, 0, {"transformer": "m", "identified": None}, gaits) for s in run.specs)
    assert {t.action_noise for t in plain} == {0.0} and {t.action_noise for t in noisy} == {0.05}
    assert [t.seed for t in plain] == [t.seed for t in noisy]  # the same episode seeds: paired
    assert len(gat) == 2 * 3 and {t.action_noise for t in gat} == {0.03}  # every episode, not one per gait


def test_the_mean_real_world_walks_at_the_middle_of_every_effect_range(tmp_path):
    """``real:mean=1``: the real world's episodes on the real world's own training seeds, with every
    effect fixed at the middle of its range (``experiments.runtime.worlds.mean_profile``): an episode
    draws exactly those values, whatever its seed, while the plain real world draws others."""
    from envs.effects import EFFECTS, PROFILES
    from experiments.fidelity.run import Fidelity
    from experiments.runtime.tasks import EpisodeTask
    from experiments.runtime.worlds import mean_profile, real_profile, world_env

    m = parse_world("real:mean=1")
    assert m.get("mean") and not parse_world("real").get("mean") and m.key != parse_world("real").key
    mp = mean_profile(PROFILES["real"])
    assert mp.name == "real:mean" and mp.latency_s == (0.015, 0.015) and mp.terrain_amplitude == (0.01, 0.01)
    assert all(lo == hi for lo, hi in (getattr(mp, f) for f in EFFECTS))
    assert real_profile("real", None) is PROFILES["real"]
    with pytest.raises(ValueError, match="NAME:mean"):
        real_profile("real:median", None)
    cfg = FidelityConfig(worlds=("real", "real:mean=1"), gaits=2, real_trials=2, episodes=2, data_seeds=1)
    run = Fidelity(cfg, str(tmp_path), executor=None)
    gaits = [{"name": "a", "theta": [0.0]}, {"name": "b", "theta": [1.0]}]
    none = {"transformer": None, "identified": None}
    plain, mean = (run.world_tasks(s, 0, none, gaits) for s in run.specs)
    assert [t.seed for t in plain] == [t.seed for t in mean]  # paired: only the physics differs
    assert {t.profile for t in mean} == {"real:mean"} and {t.profile for t in plain} == {"real"}
    env = world_env(EpisodeTask("real", [0.0], 0, profile="real:mean"))
    for seed in (1, 2):
        env.reset(seed=seed)
        e = env.unwrapped.effects
        assert e.latency_s == pytest.approx(0.015) and e.terrain_amplitude == pytest.approx(0.01)
        assert np.allclose(e.kp_scale, 0.925) and np.allclose(e.foot_friction, 0.7)
    real = world_env(EpisodeTask("real", [0.0], 0))
    real.reset(seed=1)
    assert not np.allclose(real.unwrapped.effects.kp_scale, 0.925)


def test_worlds_one_setting_apart_are_paired():
    """Beside the fixed pairs (every world against the plain sim, a variant against its plain kind,
    SGAT − GAT, hybrid − identified, hybrid − SGAT), any two worlds of one kind that differ in one
    setting are tested against each other, never worlds two settings apart; with the real world
    itself in the run, every world that learns from real data or adds noise is paired against it."""
    from experiments.fidelity.scoring import world_pairs

    names = ["sim", "hybrid", "hybrid:alpha=0.3", "hybrid:alpha=0.3:delay=auto", "sgat:alpha=0.3", "sgat:alpha=0.3:ensemble=1"]
    pairs = world_pairs(names)
    assert ("hybrid:alpha=0.3:delay=auto", "hybrid:alpha=0.3") in pairs
    assert ("hybrid:alpha=0.3:delay=auto", "hybrid") in pairs  # a variant against its plain kind
    assert ("sgat:alpha=0.3", "hybrid:alpha=0.3") not in pairs  # another kind
    assert ("sgat:alpha=0.3:ensemble=1", "sgat:alpha=0.3") in pairs and ("hybrid:alpha=0.3:delay=auto", "hybrid") in pairs
    names = ["sim", "ane", "gat", "sgat", "identified", "hybrid:alpha=0.3", "real:mean=1", "real"]
    pairs = world_pairs(names)
    assert sorted(a for a, b in pairs if b == "real") == sorted(["ane", "gat", "sgat", "identified", "hybrid:alpha=0.3",
                                                                 "real:mean=1"])
    assert ("real", "sim") in pairs and ("sim", "real") not in pairs and ("sgat", "gat") in pairs
    assert not any(b == "real" for _, b in world_pairs(names[:-1]))


def test_a_run_without_a_terminal_reports_progress_within_a_chunk(tmp_path, monkeypatch):
    """Episodes are saved in chunks of 150; without a terminal the count and an ETA still go out as the
    executor's batches end, so 160 real trials (one chunk and a bit, minutes long) show their progress."""
    import experiments.runtime.batch
    from experiments.runtime.progress import Reporter
    from experiments.runtime.rundir import EpisodeLog

    def fake_map(ex, tasks, progress=None):
        for _ in tasks:
            progress(1)
        return [types.SimpleNamespace(fitness=1.0, speed_cm_s=1.0, fell=False, steps=750) for _ in tasks]

    monkeypatch.setattr(experiments.runtime.batch, "map_episodes", fake_map)
    lines: list[str] = []
    report = Reporter.to(lines.append)
    report.every_s = -1.0  # a line at every batch
    log = EpisodeLog(str(tmp_path), {}, "run", reporter=report)
    log.run(None, [types.SimpleNamespace(key=f"k{i}") for i in range(160)], "real trials")
    counts = [ln.split("] ", 1)[1] for ln in lines if "ETA" in ln]
    assert counts[0].startswith("real trials: 1/160, ETA ") and counts[-1].startswith("real trials: 159/160, ETA ")
    assert len(counts) == 159  # every batch but the last, which ends the run
    assert lines[-1].split("] ", 1)[1].startswith("real trials: done in") and len(log.done) == 160

