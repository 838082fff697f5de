"""Executors return identical results; crashed workers are reported and their task retried once."""

import os
import sys

import pytest

sys.path.insert(0, os.path.dirname(__file__))  # so worker processes can import the task module
import _executor_tasks as T  # noqa: E402

from experiments.runtime.executors import ProcessExecutor, SerialExecutor, TaskFailed, make_executor  # noqa: E402


@pytest.fixture(autouse=True)
def _pythonpath(monkeypatch):
    here = os.path.dirname(os.path.abspath(__file__))
    root = os.path.dirname(here)
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([here, root, os.environ.get("PYTHONPATH", "")]))


def test_serial_and_process_pool_identical():
    seeds = [3, 1, 4, 1, 5]
    serial = SerialExecutor().map(T.short_rollout, seeds)
    with ProcessExecutor(2) as ex:
        done = []
        pooled = ex.map(T.short_rollout, seeds, progress=done.append)
    assert pooled == serial  # bit-identical, in task order
    assert len(done) == len(seeds)
    assert serial[1] == serial[3] and serial[0] != serial[1]


def test_crashed_worker_is_retried_once(tmp_path, capsys):
    tasks = [(str(tmp_path / "m0"), 1), (str(tmp_path / "m1"), 2)]
    with ProcessExecutor(2) as ex:
        assert ex.map(T.crash_once, tasks) == [2, 4]
    assert "worker died" in capsys.readouterr().err


def test_task_that_always_crashes_fails_clearly():
    with ProcessExecutor(1) as ex, pytest.raises(TaskFailed, match="twice"):
        ex.map(T.always_crash, [0])


def test_exception_retried_then_reported(tmp_path):
    with pytest.warns(UserWarning, match="retrying once"):
        assert SerialExecutor().map(T.raise_once, [(str(tmp_path / "s"), 1)]) == [2]
    with ProcessExecutor(1) as ex, pytest.warns(UserWarning, match="retrying once"):
        assert ex.map(T.raise_once, [(str(tmp_path / "p"), 1)]) == [2]


def test_make_executor():
    assert isinstance(make_executor(1), SerialExecutor)
    assert isinstance(make_executor(None), ProcessExecutor)
    with pytest.raises(ValueError, match="workers"):
        make_executor(0)


@pytest.mark.slow
def test_serial_pool_and_ray_give_identical_walk_fitness():
    """Walk episodes (the optimizer's tasks) through all three executors, a local Ray cluster too."""
    pytest.importorskip("ray")
    import dataclasses

    from experiments.runtime.tasks import EpisodeTask, run_episode
    from walk_engine import GaitParams

    theta = tuple(GaitParams.initial().to_array().tolist())
    tasks = [EpisodeTask(world=w, theta=theta, seed=s, seconds=2.0) for w in ("sim", "real") for s in (1, 2)]

    def outcome(results):  # every field but the wall time
        return [{k: v for k, v in dataclasses.asdict(r).items() if k != "wall_s"} for r in results]

    serial = outcome(SerialExecutor().map(run_episode, tasks))
    with ProcessExecutor(2) as ex:
        pooled = outcome(ex.map(run_episode, tasks))
    ray_ex = make_executor(ray_address="local")
    try:
        on_ray = outcome(ray_ex.map(run_episode, tasks))
    finally:
        ray_ex.close()
    assert serial == pooled == on_ray
    assert len({r["fitness"] for r in serial}) > 1
