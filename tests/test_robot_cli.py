"""``--robot g1|talos`` on the commands: the robot reaches the worlds, the gait
parameters are the robot's, recordings say which robot, and the NAO-only parts refuse clearly."""

import json

import pytest

from envs import Recording
from experiments import cli
from robots import get_robot
from walk_engine import GaitParams, params_for


def _run(capsys, *argv):
    code = cli.main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_walk_g1_records_the_robot_and_its_gait(tmp_path, capsys):
    P = params_for(get_robot("g1"))
    theta = P.initial().replace(step_length=0.09).save(tmp_path / "g1.json")
    rec_path = tmp_path / "g1.parquet"
    code, out, err = _run(capsys, "walk", "--robot", "g1", "--params", str(theta), "--seconds", "3",
                          "--record", str(rec_path), "--json")
    assert code == 0, err
    res = json.loads(out)
    assert res["robot"] == "g1" and res["params"]["step_length"] == pytest.approx(0.09) and not res["fell"]
    rec = Recording.from_parquet(rec_path)
    assert rec.meta["robot"] == "g1" and rec.robot.name == "g1" and rec.group("q").shape[1] == 29


def test_gait_files_of_one_robot_are_refused_for_another(tmp_path, capsys):
    nao_theta = GaitParams().save(tmp_path / "nao.json")
    code, _, err = _run(capsys, "walk", "--robot", "g1", "--params", str(nao_theta), "--seconds", "1")
    # the NAO file has no robot key, so it is read as G1 values: out of the G1's bounds -> one line
    assert code == 2 and "out of bounds" in err and "Traceback" not in err
    g1_theta = params_for(get_robot("g1")).initial().save(tmp_path / "g1.json")
    code, _, err = _run(capsys, "walk", "--params", str(g1_theta), "--seconds", "1")
    assert code == 2 and "robot 'g1', not 'nao'" in err


def test_identified_world_is_the_naos(capsys):
    code, _, err = _run(capsys, "walk", "--robot", "talos", "--world", "identified", "--report", "README.md")
    assert code == 2 and "NAO only" in err


@pytest.mark.parametrize("robot", ["g1", "talos"])
def test_stand_json_names_the_robot(robot, capsys):
    code, out, err = _run(capsys, "stand", "--robot", robot, "--seconds", "1", "--world", "sim", "--json")
    assert code == 0, err
    res = json.loads(out)
    assert res["robot"] == robot and not res["worlds"][0]["fell"]
    assert sum(res["worlds"][0]["foot_force_n"]) == pytest.approx(get_robot(robot).total_mass * 9.81, rel=0.1)


def test_optimize_g1_tiny_run(tmp_path, capsys):
    """A whole (tiny) grounding + CMA-ES run on the G1: every episode is a G1 walk."""
    out = tmp_path / "run"
    code, text, err = _run(capsys, "optimize", "--robot", "g1", "--methods", "sgat:epochs=5:real=1:sim=1",
                           "--grounding-steps", "1", "--popsize", "2", "--generations", "1",
                           "--select-episodes", "1", "--eval-trials", "1", "--seconds", "1",
                           "--workers", "1", "--out", str(out), "--json")
    assert code == 0, err
    res = json.loads(text)
    assert res["robot"] == "g1"
    data = sorted((out / "data").glob("*.parquet"))
    assert data and all(Recording.from_parquet(p).meta["robot"] == "g1" for p in data)
    P = params_for(get_robot("g1"))
    assert P.load(next((out / "thetas").glob("*.json"))).step_period > 0.3  # a G1 gait, G1 bounds


def test_optimize_refuses_identified_methods_for_other_robots(capsys):
    code, _, err = _run(capsys, "optimize", "--robot", "g1", "--methods", "hybrid")
    assert code == 2 and "NAO only" in err


def test_stress_talos_tiny_run(tmp_path, capsys):
    code, text, err = _run(capsys, "stress", "--robot", "talos", "--world", "sim", "--trials", "1", "--amplitude",
                           "0", "--seconds", "1", "--workers", "1", "--out", str(tmp_path / "s"), "--json")
    assert code == 0, err
    res = json.loads(text)
    assert res["rows"][0]["trials"] == 1 and res["rows"][0]["falls"] == 0
