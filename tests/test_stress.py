"""``sgatwalk stress``: input checks, Wilson intervals, paired seeds, resume, sweep, --rerun, JSON."""

import json
import shutil

import pytest

from experiments import cli
from experiments.runtime.tasks import EpisodeTask, run_episode
from experiments.runtime.worlds import terrain_field
from experiments.stress import run as S
from experiments.runtime.executors import SerialExecutor, make_executor
from walk_engine import GaitParams


def _cli(capsys, *argv):
    code = cli.main(["stress", *argv])
    out = capsys.readouterr()
    return code, out.out, out.err


# ------------------------------------------------------------------------------------ pure parts
def test_parse_levels():
    assert S.parse_levels("0:0.04:9") == [0.0, 0.005, 0.01, 0.015, 0.02, 0.025, 0.03, 0.035, 0.04]
    assert S.parse_levels("0.01, 0.02,0.01") == [0.01, 0.02]
    assert S.parse_levels("0.02") == [0.02] and S.parse_levels(0.03) == [0.03]
    assert S.parse_levels("0:0.02:1") == [0.0]
    for bad, words in [("0:0.04:0", "empty range"), ("0:0.04:-2", "empty range"), ("0:0.04:2.5", "empty range"),
                       ("0.01:0.01:3", "empty range"), ("", "no values"), ("a:b:c", "malformed"),
                       ("0:1", "malformed"), ("nan", "finite")]:
        with pytest.raises(ValueError, match=words):
            S.parse_levels(bad)


def test_trial_seeds_shared_and_distinct():
    assert S.trial_seeds(0, 3) == S.trial_seeds(0, 3)
    seeds = {S.trial_seeds(0, j) for j in range(20)} | {S.trial_seeds(1, j) for j in range(20)}
    assert len(seeds) == 40


def test_plan_pairs_policies_and_levels(tmp_path):
    a = GaitParams().save(tmp_path / "a.json")
    b = GaitParams(step_length=0.05).save(tmp_path / "b.json")
    cfg = S.make_config([a, b], world="sim", amplitude="0:0.02:3", trials=2)
    tasks = S.plan_tasks(cfg)
    assert len(tasks) == 2 * 3 * 2 and [p.label for p in cfg.policies] == ["a", "b"]
    # every (level, trial) has one terrain seed shared by both policies; levels share it too
    for j in range(2):
        ts = {(t.terrain_seed, t.episode_seed, t.task.seed) for t in tasks if t.trial == j}
        assert len(ts) == 1
    assert {t.task.terrain for t in tasks if t.trial == 0} == {("lumpy", tasks[0].terrain_seed, v) for v in (0.0, 0.01, 0.02)}


def test_same_heightfield_in_sim_and_real():
    """A (level, trial) is the same ground in both worlds: the recorded terrains agree."""
    ts, es = S.trial_seeds(0, 1)
    metas = {}
    for world, profile in (("sim", "real"), ("real", S.make_config(world="real").profile)):
        res = run_episode(EpisodeTask(world, GaitParams().to_array(), es, 0.1, profile=profile,
                                      terrain=("fractal", ts, 0.02), record=True))
        metas[world] = res.recording[1]["terrain"]
        assert res.terrain == metas[world]["name"]
    assert metas["sim"] == metas["real"] and metas["sim"]["max"] == pytest.approx(0.02, abs=1e-3)
    assert terrain_field("fractal", ts, 0.02) is terrain_field("fractal", ts, 0.02)  # cached per process


def test_worst_trial_is_earliest_fall_else_slowest():
    cfg = S.make_config(world="sim", amplitude="0.01", trials=3)
    h = cfg.policies[0].theta_hash
    rows = [{"policy": "theta0", "theta_hash": h, "level": 0.01, "trial": 0, "fell": True, "fall_time_s": 4.0, "speed_cm_s": 3.0},
            {"policy": "theta0", "theta_hash": h, "level": 0.01, "trial": 1, "fell": True, "fall_time_s": 2.0, "speed_cm_s": 5.0},
            {"policy": "theta0", "theta_hash": h, "level": 0.01, "trial": 2, "fell": False, "fall_time_s": None, "speed_cm_s": 1.0}]
    assert S.worst_trials(rows, cfg)[("theta0", 0.01)]["trial"] == 1
    assert S.worst_trials(rows[2:] + [dict(rows[2], trial=0, speed_cm_s=0.5)], cfg)[("theta0", 0.01)]["trial"] == 0


# ------------------------------------------------------------------------------------ bad input
@pytest.mark.parametrize("argv, words", [
    (["--terrain", "gravel"], "unknown terrain 'gravel'"),
    (["--terrain", "flat"], "amplitude 0"),
    (["--amplitude", "0:0.04:0"], "empty range"),
    (["--amplitude", "0.02:0.02:5"], "empty range"),
    (["--amplitude=-0.01,0.01"], ">= 0"),
    (["--trials", "0"], "argument --trials: must be in [1, 100000]"),
    (["--params", "/nonexistent/theta.json"], "argument --params: no such file"),
    (["--world", "sim", "--profile", "real"], "real world only"),
    (["--world", "sim", "--sweep", "latency_s=0:0.04:5"], "--world real"),
    (["--sweep", "lag=0:0.04:5"], "unknown effect 'lag'"),
    (["--sweep", "latency_s"], "EFFECT=lo:hi:n"),
    (["--sweep", "foot_friction=0:0.8:3"], "physical domain"),
    (["--sweep", "latency_s=0:0.04:3", "--terrain", "lumpy", "--amplitude", "0:0.02:3"], "one terrain amplitude"),
    (["--profile", "moon"], "unknown profile"),
    (["--sweep", "mass_scale=0.9:1.2:4", "--amplitude", "0.02"], "needs --terrain"),
])
def test_bad_input_is_a_one_line_error(capsys, tmp_path, argv, words):
    code, out, err = _cli(capsys, *argv, "--out", str(tmp_path / "o"))
    assert code == 2 and out == "" and words in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "o").exists()  # nothing ran, nothing written


@pytest.mark.parametrize("content, words", [("{not json", "not valid JSON"),
                                            (json.dumps({"step_period": 0.3}), "missing"),
                                            (None, "directory")])
def test_unreadable_params_file(capsys, tmp_path, content, words):
    p = tmp_path / "bad.json"
    if content is None:
        p.mkdir()
    else:
        p.write_text(content)
    good = GaitParams().save(tmp_path / "good.json")
    code, out, err = _cli(capsys, "--params", str(good), str(p), "--out", str(tmp_path / "o"))
    assert code == 2 and words in err and "bad.json" in err


# ------------------------------------------------------------------------------------ runs
def _strip(rows):
    return [{k: v for k, v in r.items() if k not in ("policy", "wall_s")} for r in rows]


def test_identical_policies_give_identical_trials(tmp_path):
    """Paired seeds: the same gait under two names gets the same result in every trial (real world:
    effects, sensor noise and terrain all come from the shared seeds), whichever executor."""
    a = GaitParams(step_length=0.05).save(tmp_path / "a.json")
    shutil.copy(a, tmp_path / "b.json")
    cfg = S.make_config([a, tmp_path / "b.json"], world="real", amplitude="0.025", trials=2, seconds=1.0)
    with make_executor(2) as ex:
        res = S.run_stress(cfg, tmp_path / "run", executor=ex)
    rows = S.read_trials(tmp_path / "run" / "trials.csv")
    by = {p: sorted((r for r in rows if r["policy"] == p), key=lambda r: r["trial"]) for p in ("a", "b")}
    assert len(by["a"]) == len(by["b"]) == 2
    assert _strip(by["a"]) == _strip(by["b"])
    assert by["a"][0]["speed_cm_s"] != by["a"][1]["speed_cm_s"]  # the trials themselves differ
    ra, rb = res["rows"]
    assert {**ra, "policy": "b"} == rb
    trial = S.plan_tasks(cfg)[1]
    serial = S.trial_row(trial, run_episode(trial.task))  # a process-pool row repeats exactly in this process
    assert _strip([serial])[0] == _strip([r for r in by["b"] if r["trial"] == 0])[0]


class _Interrupt(SerialExecutor):
    """Serial executor that is "interrupted" (KeyboardInterrupt) on its map call number ``stop``."""

    def __init__(self, stop):
        self.calls, self.stop, self.ran = 0, stop, 0

    def map(self, fn, tasks, progress=None, weights=None):
        self.calls += 1
        if self.calls == self.stop:
            raise KeyboardInterrupt
        self.ran += sum(weights) if weights else len(tasks)  # a task may be a batch of episodes
        return super().map(fn, tasks, progress, weights)


def test_resume_where_it_stopped(tmp_path):
    out = tmp_path / "run"
    cfg = S.make_config(world="sim", amplitude="0,0.03", trials=3, seconds=0.5)  # 6 episodes
    ex = _Interrupt(stop=2)
    with pytest.raises(KeyboardInterrupt):
        S.run_stress(cfg, out, executor=ex, chunk=4)
    assert len(S.read_trials(out / "trials.csv")) == 4  # the first chunk was saved
    ex = _Interrupt(stop=0)
    res = S.run_stress(cfg, out, executor=ex, chunk=4)
    assert (res["ran"], res["resumed"], ex.ran) == (2, 4, 2)
    assert [r["trials"] for r in res["rows"]] == [3, 3]
    # more trials later: only the new ones run; the table covers all of them
    cfg4 = S.make_config(world="sim", amplitude="0,0.03", trials=4, seconds=0.5)
    ex = _Interrupt(stop=0)
    res = S.run_stress(cfg4, out, executor=ex)
    assert (res["ran"], res["resumed"], ex.ran) == (2, 6, 2) and [r["trials"] for r in res["rows"]] == [4, 4]
    # a full re-run of the same thing gives the same rows as the resumed one
    full = S.run_stress(cfg4, tmp_path / "fresh", executor=SerialExecutor())
    assert _strip(S.read_trials(tmp_path / "fresh" / "trials.csv")) == _strip(S.read_trials(out / "trials.csv"))
    assert full["rows"] == res["rows"]
    # other settings in the same directory: refused
    with pytest.raises(ValueError, match="other settings.*world"):
        S.run_stress(S.make_config(world="real", amplitude="0", trials=1, seconds=0.5), out, executor=ex)


def test_cli_json_table_csv_png(capsys, tmp_path):
    code, out, err = _cli(capsys, "--world", "sim", "--amplitude", "0,0.03", "--trials", "2", "--seconds", "0.5",
                          "--workers", "1", "--out", str(tmp_path / "run"), "--json")
    assert code == 0, err
    res = json.loads(out)
    keys = {"policy", "level", "trials", "falls", "fall_rate", "fall_rate_ci95", "speed_cm_s_mean", "speed_cm_s_std"}
    assert len(res["rows"]) == 2 and all(keys <= set(r) for r in res["rows"])
    r0 = res["rows"][0]
    assert r0["policy"] == "theta0" and r0["level"] == 0.0 and r0["trials"] == 2 and r0["falls"] == 0
    assert r0["fall_rate"] == 0.0 and r0["fall_rate_ci95"][0] == 0.0 and 0.5 < r0["fall_rate_ci95"][1] < 0.7
    for k in ("trials_csv", "trials_parquet", "summary_csv", "png"):
        assert (tmp_path / "run" / res["files"][k].split("/")[-1]).stat().st_size > 0
    import pyarrow.parquet as pq

    assert pq.read_table(res["files"]["trials_parquet"]).num_rows == 4
    from matplotlib.image import imread

    img = imread(res["files"]["png"])
    assert img.shape[0] > 500 and img.shape[1] > 500
    # human output: the table
    code, out, err = _cli(capsys, "--world", "sim", "--amplitude", "0,0.03", "--trials", "2", "--seconds", "0.5",
                          "--workers", "1", "--out", str(tmp_path / "run"))
    assert code == 0 and "policy theta0" in out and "fall rate" in out and "4 resumed" in out


def test_sweep_latency_with_rerun(tmp_path):
    """--sweep fixes the effect at each level (seen in the worst trial's recording, --rerun)."""
    cfg = S.make_config(world="real", profile="none", sweep="latency_s=0,0.02", trials=1, seconds=0.5, terrain=None)
    assert cfg.axis == "latency_s" and cfg.level_name == "latency_s [s]"
    res = S.run_stress(cfg, tmp_path / "run", executor=SerialExecutor(), rerun=True)
    assert [r["level"] for r in res["rows"]] == [0.0, 0.02]
    assert len(res["worst"]) == 2 and all(w["repeats"] for w in res["worst"])
    rrd = tmp_path / "run" / "rerun" / "theta0.rrd"
    assert rrd.stat().st_size > 0 and res["files"]["rrd"] == [str(rrd)]
    rows = S.read_trials(tmp_path / "run" / "trials.csv")
    assert {r["terrain"] for r in rows} == {"flat"}  # profile none: no random terrain
    # the effect value reaches the world
    t = S.plan_tasks(cfg)[1].task.replace(record=True)
    assert run_episode(t).recording[1]["effects"]["latency_s"] == 0.02
