"""The experiments on a real local Ray cluster (``ray start --head`` bound to loopback, 2 CPUs).

Every command's results through ``--ray-address`` equal the process pool's bit for bit; a Ray worker
killed mid-run is replaced and its task rerun with the same result; a driver killed mid-run resumes
from its run directory without redoing what was saved; a job that raises stops the run with an
error naming it and leaves the run directory as it was. The cluster is stopped whatever happens.
"""

from __future__ import annotations

import atexit
import csv
import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

RAY = str(Path(sys.executable).with_name("ray"))
ROOT = Path(__file__).resolve().parents[1]
#: Keys whose values are wall times, machines or paths: what legitimately differs between two runs.
VOLATILE = {"wall_s", "elapsed_s", "realtime_factor", "job_wall_s", "cpu_s", "phases_s", "generation_s", "run_dir",
            "out", "files", "executor", "workers", "at", "load_average", "seconds_per_generation", "timing", "text",
            "table", "ran", "resumed", "new_rows", "finished_at", "started_at"}
#: A grounded world with one real and one sim walk per grounding step and short model fits (tiny runs).
SGAT = "sgat:epochs=20:real=1:sim=1"


def _trials(run_dir: Path) -> list[dict]:
    """A stress run's ``trials.csv`` rows (as text), without their wall times."""
    with open(run_dir / "trials.csv", newline="") as f:
        return [{k: v for k, v in row.items() if k not in VOLATILE} for row in csv.DictReader(f)]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _interrupt(signum, frame):
    raise KeyboardInterrupt(f"signal {signum}")


@pytest.fixture(scope="module")
def cluster():
    """A Ray head on 127.0.0.1 with 2 CPUs, its address; stopped (``ray stop --force``) at the end, also
    when the tests are stopped by SIGTERM (e.g. a CI time limit): SIGTERM is turned into
    KeyboardInterrupt while the cluster runs, and the stop is registered with ``atexit`` too."""
    temp = tempfile.mkdtemp(prefix="ray", dir="/tmp")  # short: Ray's socket paths are limited to 107 bytes
    port = _free_port()
    # Token authentication (Ray >= 2.52; on by default where ~/.ray/auth_token exists): a fresh token for
    # this cluster, given to the head and, through the environment, to every command the tests run.
    # Ray replaces a node address of 127.0.0.1 by the machine's outward IP unless clusters of several
    # machines are off (RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0, as on macOS): then every address is loopback.
    # Ray starts its workers at nice 15 (its worker_niceness); at 0 they share the cores fairly with
    # whatever else runs (the other long tests beside them in .ci/run) instead of waiting for it to end.
    auth = {"RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": secrets.token_hex(32), "RAY_USAGE_STATS_ENABLED": "0",
            "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "0", "RAY_worker_niceness": "0"}
    saved = {k: os.environ.get(k) for k in auth}
    os.environ.update(auth)
    env = dict(os.environ)
    stopped = []

    def stop():
        if not stopped:
            stopped.append(True)
            subprocess.run([RAY, "stop", "--force"], env=env, timeout=300, capture_output=True)
            shutil.rmtree(temp, ignore_errors=True)

    atexit.register(stop)
    try:
        old_term = signal.signal(signal.SIGTERM, _interrupt)
    except ValueError:  # not the main thread: SIGTERM stays as it is
        old_term = None
    try:
        pytest.importorskip("ray")  # the dev install has it; this only names the cause where it is missing
        subprocess.run([RAY, "start", "--head", "--node-ip-address", "127.0.0.1", "--port", str(port),
                        "--num-cpus", "2", "--include-dashboard=false", "--disable-usage-stats", f"--temp-dir={temp}"],
                       check=True, env=env, timeout=300, capture_output=True)
        yield f"127.0.0.1:{port}"
    finally:
        if old_term is not None:
            signal.signal(signal.SIGTERM, old_term)
        stop()
        atexit.unregister(stop)
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _strip(doc):
    """``doc`` without :data:`VOLATILE` keys (recursively)."""
    if isinstance(doc, dict):
        return {k: _strip(v) for k, v in doc.items() if k not in VOLATILE}
    if isinstance(doc, list):
        return [_strip(v) for v in doc]
    if isinstance(doc, float) and doc != doc:
        return "nan"  # NaN != NaN: an empty cell compares equal to an empty cell
    return doc


def _cli(args: list[str], **kw) -> subprocess.CompletedProcess:
    """``python -m experiments.cli ARGS --json`` in a fresh process (as a user runs it)."""
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "experiments.cli", *args, "--json"], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=1800, **kw)


def _same_on_pool_and_ray(tmp_path, cluster, args: list[str], result_file: str):
    """Run ``args`` on a 2-process pool and on the cluster into two run directories; their result files
    (JSON) must be equal but for wall times and paths."""
    docs = []
    for name, where in (("pool", ["--workers", "2"]), ("ray", ["--ray-address", cluster])):
        out = tmp_path / name
        r = _cli([*args, *where, "--out", str(out)])
        assert r.returncode == 0, r.stderr[-3000:]
        docs.append(_strip(json.loads((out / result_file).read_text())))
    assert docs[0] == docs[1]
    return docs[0]


def test_optimize_on_ray_equals_the_pool(tmp_path, cluster):
    doc = _same_on_pool_and_ray(tmp_path, cluster, [
        "optimize", "--methods", f"{SGAT},sim", "--generations", "1", "--popsize", "4", "--eval-trials", "2",
        "--select-episodes", "2", "--grounding-steps", "1", "--seconds", "0.8"], "results.json")
    assert {r["method"] for r in doc["rows"]} == {"theta0", SGAT, "sim"}


def test_fidelity_on_ray_equals_the_pool(tmp_path, cluster):
    doc = _same_on_pool_and_ray(tmp_path, cluster, [
        "fidelity", "--worlds", "sim", "gat", "real", "--gaits", "2", "--real-trials", "2", "--data-seeds", "2",
        "--episodes", "2", "--seconds", "0.8"], "fidelity.json")
    assert len(doc["worlds"]["gat"]["draws"]) == 2  # two draws: two jobs


def test_table1_on_ray_equals_the_pool(tmp_path, cluster):
    doc = _same_on_pool_and_ray(tmp_path, cluster, [
        "table1", "--methods", f"{SGAT},sim", "--seeds", "2", "--trials", "2", "--popsize", "3", "--generations", "1",
        "--grounding-steps", "1", "--seconds", "0.8"], "table1.json")
    assert {r["method"] for r in doc["rows"]} >= {SGAT, "sim"}


def test_stress_on_ray_equals_the_pool(tmp_path, cluster):
    doc = _same_on_pool_and_ray(tmp_path, cluster, [
        "stress", "--trials", "2", "--amplitude", "0,0.02", "--seconds", "1"], "stress.json")
    for name in ("pool", "ray"):
        assert (tmp_path / name / "trials.csv").exists()
    assert len(_trials(tmp_path / "pool")) == 4 and _trials(tmp_path / "pool") == _trials(tmp_path / "ray")
    assert doc


def test_gym_on_ray_equals_the_pool(tmp_path, cluster):
    args = ["gym", "--preset", "quick", "--noise", "0.2", "--methods", "sim,gat", "--runs", "1", "--sim-steps", "1000",
            "--grounded-steps", "1000", "--real-steps", "1000", "--eval-episodes", "2"]
    import pyarrow.parquet as pq

    tables = []
    for name, where in (("pool", ["--workers", "2"]), ("ray", ["--ray-address", cluster])):
        r = _cli([*args, *where, "--out", str(tmp_path / name)])
        assert r.returncode == 0, r.stderr[-3000:]
        rows = pq.read_table(next((tmp_path / name).glob("results*.parquet"))).to_pylist()
        tables.append(sorted((_strip(x) for x in rows), key=lambda x: (x["method"], x["noise"], x["run"])))
    assert tables[0] == tables[1] and {x["method"] for x in tables[0]} == {"sim", "gat"}


def _ray_workers(kind: str) -> list[int]:
    """PIDs of the Ray worker processes now running ``kind`` (their process title is ``ray::<function>``)."""
    pids = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                cmd = (d / "cmdline").read_bytes().split(b"\0")[0].decode(errors="replace")
            except OSError:
                continue
            if cmd.startswith(f"ray::{kind}"):
                pids.append(int(d.name))
    return pids


def test_a_killed_ray_worker_is_replaced_and_its_task_rerun(tmp_path, cluster):
    """SIGKILL the worker running an episode batch mid-run: Ray reruns the task on a new worker and the
    result equals an undisturbed run's."""
    args = ["stress", "--trials", "4", "--amplitude", "0,0.02", "--seconds", "2", "--ray-address", cluster]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "experiments.cli", *args, "--out", str(tmp_path / "killed"), "--json"],
                            cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    killed = None
    try:
        deadline = time.time() + 600
        while killed is None and proc.poll() is None and time.time() < deadline:
            busy = _ray_workers("_in_worker")
            if busy:
                time.sleep(0.5)  # well into the task
                try:
                    os.kill(busy[0], signal.SIGKILL)
                    killed = busy[0]
                except ProcessLookupError:
                    pass
            time.sleep(0.05)
        out, err = proc.communicate(timeout=1200)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert killed is not None, "no Ray worker ran a task"
    assert proc.returncode == 0, err[-3000:]
    ref = _cli([*args, "--out", str(tmp_path / "undisturbed")])
    assert ref.returncode == 0, ref.stderr[-3000:]
    assert _trials(tmp_path / "killed") == _trials(tmp_path / "undisturbed")


def test_a_killed_driver_resumes_without_redoing_what_was_saved(tmp_path, cluster):
    """SIGKILL ``sgatwalk table1`` on the cluster once its first optimization has saved a generation; the
    same command resumes it: what was saved stays as it was, and the result equals an undisturbed run's."""
    args = ["table1", "--methods", f"{SGAT},sim", "--seeds", "1", "--trials", "2", "--popsize", "3", "--generations", "2",
            "--grounding-steps", "1", "--seconds", "0.8", "--ray-address", cluster]
    run = tmp_path / "killed"
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "experiments.cli", *args, "--out", str(run), "--json"], cwd=ROOT,
                            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    saved = run / "opt_seed0" / "sim" / "generations.csv"
    try:
        deadline = time.time() + 900
        while not saved.exists() and proc.poll() is None and time.time() < deadline:
            time.sleep(0.1)
        assert saved.exists(), "no generation saved before the driver ended"
        before = saved.read_text()
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    r = _cli(args + ["--out", str(run)])
    assert r.returncode == 0, r.stderr[-3000:]
    assert saved.read_text().startswith(before)  # the generation saved before the kill was kept, not redone
    ref = _cli(args + ["--out", str(tmp_path / "undisturbed")])
    assert ref.returncode == 0, ref.stderr[-3000:]
    assert _strip(json.loads((run / "table1.json").read_text())) == \
        _strip(json.loads((tmp_path / "undisturbed" / "table1.json").read_text()))


def test_a_job_that_raises_names_itself_and_leaves_the_run_directory(tmp_path, cluster):
    """A coarse job that raises fails the run with TaskFailed naming the job; the files the jobs
    wrote stay (a resume starts from them). Run as its own driver process, as a command would be (Ray
    reads its authentication settings when it is first imported)."""
    script = f"""
import sys
sys.path.insert(0, {str(Path(__file__).parent)!r})
import ray.cloudpickle
import _executor_tasks
from experiments.runtime.executors import RayExecutor, TaskFailed

ray.cloudpickle.register_pickle_by_value(_executor_tasks)  # the workers cannot import the tests' helpers
jobs = [({str(tmp_path)!r} + f"/job{{i}}.txt", i == 1) for i in range(3)]
ex = RayExecutor({cluster!r})
try:
    ex.jobs(_executor_tasks.write_then_fail, jobs, [f"seed {{i}}" for i in range(3)])
    print("no error")
except TaskFailed as exc:
    print(f"TaskFailed: {{exc}}")
finally:
    ex.close()
"""
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": str(ROOT)}
    r = subprocess.run([sys.executable, "-c", script], cwd=ROOT, env=env, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    assert "TaskFailed: job seed 1 failed: ValueError: bad input in job 1" in r.stdout, r.stdout + r.stderr[-2000:]
    assert (tmp_path / "job1.txt").read_text() == "started"  # what it wrote before it raised is still there
