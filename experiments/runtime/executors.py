"""Executors: run ``fn(task)`` for many tasks, serially, in a local process pool, or on Ray.

Every task carries its own seed, so results never depend on the executor or on the order tasks
finish in (docs/architecture.md, "Conventions"). ``map`` returns results in task order; ``jobs``
runs coarse independent jobs (one optimization, one draw of real data), one after the other locally
and side by side on a Ray cluster.

* :class:`SerialExecutor` -- in this process (tests, debugging).
* :class:`ProcessExecutor` -- the default: ``concurrent.futures.ProcessPoolExecutor`` with the
  ``forkserver`` start method, one worker per core, ``OMP_NUM_THREADS=1`` and one torch thread per
  worker. A worker that dies (segfault, OOM kill) breaks the pool: the pool is rebuilt and the
  unfinished tasks are re-submitted; a task that fails twice raises :class:`TaskFailed`.
* :class:`RayExecutor` -- only when a cluster address is given (``--ray-address``); ``ray`` is
  imported lazily. Ray runs a task whose worker died again, up to three times.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing as mp
import os
import sys
import warnings
from concurrent.futures.process import BrokenProcessPool
from typing import Any, Callable, Sequence


def limit_blas_threads() -> int:
    """Run the BLAS and OpenMP pools loaded in this process with ``OMP_NUM_THREADS`` threads (1 unless
    set; ``threadpoolctl.threadpool_limits``), and those loaded later too (the variable is set).

    The sgatwalk command runs its numerical work in process-pool workers of one thread each, and the
    rounding of a threaded BLAS reduction depends on its thread count: the engine-gap calibration
    computed with numpy's two OpenBLAS threads differs from the one-thread result in the 12th digit, and
    the identified worlds built on it walk differently on random ground. The variable alone does not
    reach a BLAS already loaded (an entry point that imported numpy before :func:`main`).

    Returns:
        The thread count applied.
    """
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    try:
        n = max(1, int(os.environ["OMP_NUM_THREADS"]))
    except ValueError:  # e.g. a nested "4,2": leave the pools as they are
        return 0
    from threadpoolctl import threadpool_limits  # lazy: inspects the libraries loaded so far

    threadpool_limits(limits=n)
    return n


class TaskFailed(RuntimeError):
    """A task failed twice (an exception or a dead worker); the message names the task."""


def _worker_init() -> None:
    os.environ["OMP_NUM_THREADS"] = "1"
    try:
        import torch  # lazy: torch (optional here; only in workers)

        torch.set_num_threads(1)
    except ImportError:  # pragma: no cover
        pass


class SerialExecutor:
    """Run tasks one after another in this process."""

    workers = 1
    name = "serial"

    def map(self, fn: Callable, tasks: Sequence, progress: Callable[[int], None] | None = None,
            weights: Sequence[int] | None = None) -> list:
        """``[fn(t) for t in tasks]``; ``progress(w)`` after each task, ``w = weights[i]`` (default 1:
        a task that is a batch of episodes counts as its episodes)."""
        out = []
        for i, t in enumerate(tasks):
            try:
                out.append(fn(t))
            except Exception as exc:
                warnings.warn(f"task {i} raised {type(exc).__name__}: {exc}; retrying once")
                try:
                    out.append(fn(t))
                except Exception as exc2:
                    raise TaskFailed(f"task {i} failed twice: {type(exc2).__name__}: {exc2}") from exc2
            if progress:
                progress(weights[i] if weights else 1)
        return out

    def jobs(self, fn: Callable, jobs: Sequence, labels: Sequence[str] | None = None, reporter=None) -> list:
        """Run independent coarse jobs ``fn(job, executor)`` (a Table I optimization, a fidelity draw):
        here one after the other in this process, each sending its own tasks to this executor. A job
        carries its seeds and writes its own files, so the results do not depend on the executor; a job
        that raises stops the run with :class:`TaskFailed` naming it (what it saved stays saved).

        Args:
            fn: a top-level function ``fn(job, executor) -> result`` (picklable for Ray).
            jobs: the jobs' arguments; labels: their names in messages (default their indices).
            reporter: an ``experiments.runtime.progress.Reporter`` told when each job ends.

        Returns:
            The results in job order.
        """
        jobs = list(jobs)
        labels = list(labels or [str(i) for i in range(len(jobs))])
        out = []
        for i, (job, label) in enumerate(zip(jobs, labels)):
            try:
                out.append(fn(job, self))
            except Exception as exc:
                raise TaskFailed(f"job {label} failed: {type(exc).__name__}: {exc}") from exc
            if reporter is not None:
                reporter.say(f"{i + 1}/{len(jobs)} jobs done ({label})")
        return out

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class ProcessExecutor(SerialExecutor):
    """A local process pool (default: one worker per core)."""

    name = "process"

    def __init__(self, workers: int | None = None, start_method: str = "forkserver"):
        self.workers = max(1, int(workers or os.cpu_count() or 1))
        self.start_method = start_method
        self._pool: cf.ProcessPoolExecutor | None = None

    def _ensure(self) -> cf.ProcessPoolExecutor:
        if self._pool is None:
            ctx = mp.get_context(self.start_method)
            self._pool = cf.ProcessPoolExecutor(self.workers, mp_context=ctx, initializer=_worker_init)
        return self._pool

    def map(self, fn: Callable, tasks: Sequence, progress: Callable[[int], None] | None = None,
            weights: Sequence[int] | None = None) -> list:
        tasks = list(tasks)
        step = (lambda i: progress(weights[i] if weights else 1)) if progress else (lambda i: None)
        results: list[Any] = [None] * len(tasks)
        done = [False] * len(tasks)
        errors = [0] * len(tasks)
        pool = self._ensure()
        pending = {pool.submit(fn, t): i for i, t in enumerate(tasks)}
        broken = False
        for fut in cf.as_completed(pending):
            i = pending[fut]
            try:
                results[i] = fut.result()
                done[i] = True
                step(i)
            except BrokenProcessPool:
                broken = True
            except Exception as exc:
                errors[i] += 1
                warnings.warn(f"task {i} raised {type(exc).__name__}: {exc}; retrying once")
        if broken:  # a worker died: which task killed it is unknown, so re-run the lost ones alone
            self._discard()
            lost = [i for i in range(len(tasks)) if not done[i] and not errors[i]]
            print(f"executor: a worker died; rebuilt the pool and retrying {len(lost)} task(s) one by one",
                  file=sys.stderr)
            for i in lost:
                results[i] = self._isolated(fn, tasks[i], i)
                done[i] = True
                step(i)
        for i in range(len(tasks)):  # tasks that raised: one more try each
            if not done[i]:
                try:
                    results[i] = self._ensure().submit(fn, tasks[i]).result()
                except BrokenProcessPool:
                    self._discard()
                    results[i] = self._isolated(fn, tasks[i], i)
                except Exception as exc:
                    raise TaskFailed(f"task {i} failed twice: {type(exc).__name__}: {exc}") from exc
                step(i)
        return results

    def _discard(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None

    def _isolated(self, fn, task, i):
        """Run one task alone (its crash is then its own), twice at most."""
        for attempt in (1, 2):
            try:
                return self._ensure().submit(fn, task).result()
            except BrokenProcessPool:
                self._discard()
                if attempt == 2:
                    raise TaskFailed(f"task {i} killed its worker twice (crash or kill); giving up") from None
                print(f"executor: task {i} killed its worker; retrying it once", file=sys.stderr)
            except Exception as exc:
                if attempt == 2:
                    raise TaskFailed(f"task {i} failed twice: {type(exc).__name__}: {exc}") from exc
                warnings.warn(f"task {i} raised {type(exc).__name__}: {exc}; retrying once")

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None


def _in_worker(fn: Callable, arg):
    """Run ``fn(arg)`` in a Ray worker set up as the process pool's workers are (one BLAS and torch thread)."""
    _worker_init()
    return fn(arg)


def _job_in_worker(fn: Callable, job, label: str):
    """Run the coarse job ``fn(job, executor)`` in a Ray worker, its own tasks on the same cluster."""
    _worker_init()
    return fn(job, RayExecutor(None))


class RayExecutor(SerialExecutor):
    """Tasks on a Ray cluster.

    Args:
        address: the cluster's address (``"auto"``: the one started on this machine with ``ray start``,
            ``"HOST:PORT"`` of its head, ``"ray://HOST:10001"`` through Ray Client); ``"local"`` starts a
            private one-machine cluster for this process; None inside a Ray task (the cluster it runs on).

    Every task runs with one BLAS and one torch thread. A task whose worker process dies (killed, out of
    memory, a lost node) is run again, up to :attr:`RETRIES` times, with the same result (tasks carry their
    seeds); a task that raises is not retried (an exception is a bug or bad input) and fails the map with
    :class:`TaskFailed` naming it. Coarse jobs (:meth:`jobs`) run side by side as tasks of their own, each
    sending its episodes to the same cluster.

    Raises:
        ValueError: Ray is not installed, or the cluster cannot be reached (named).
    """

    name = "ray"
    #: Times a task is run again after its worker died.
    RETRIES = 3

    def __init__(self, address: str | None):
        try:
            import ray  # lazy: ray (the dev install has it; a user's may not)
        except ImportError:
            raise ValueError("--ray-address needs Ray: pip install 'sgatwalk[ray]'") from None
        self._ray = ray
        self._owns = False
        if not ray.is_initialized():
            if address is None:
                raise ValueError("no Ray cluster to join (give its address)")
            pkg_root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
            kw = dict(include_dashboard=False, log_to_driver=True,
                      runtime_env={"env_vars": {"PYTHONPATH": pkg_root, "OMP_NUM_THREADS": "1"}})
            try:
                ray.init(**kw) if address == "local" else ray.init(address=address, **kw)
            except (ConnectionError, RuntimeError, ValueError) as exc:
                why = f"{exc}" + (f" ({exc.__cause__})" if exc.__cause__ else "")
                if "auth" in why.lower():
                    why += ("; the cluster uses token authentication: give this machine the cluster's token "
                            "(RAY_AUTH_TOKEN, or ~/.ray/auth_token; docs/cluster.md)")
                raise ValueError(f"cannot reach the Ray cluster at {address!r}: {why}") from None
            self._owns = True
        self.workers = max(1, int(ray.cluster_resources().get("CPU", 1)))
        self._task = ray.remote(max_retries=self.RETRIES, retry_exceptions=False)(_in_worker)
        self._job = ray.remote(max_retries=self.RETRIES, retry_exceptions=False)(_job_in_worker)

    def _gather(self, refs: list, labels: Sequence[str], progress, weights) -> list:
        ray = self._ray
        index = {r: i for i, r in enumerate(refs)}
        out: list[Any] = [None] * len(refs)
        remaining = list(refs)
        try:
            while remaining:
                ready, remaining = ray.wait(remaining, num_returns=1)
                for r in ready:
                    i = index[r]
                    try:
                        out[i] = ray.get(r)
                    except ray.exceptions.RayTaskError as exc:  # the task raised: its own error, named
                        cause = exc.cause if getattr(exc, "cause", None) is not None else exc
                        raise TaskFailed(f"{labels[i]} failed: {type(cause).__name__}: {cause}") from cause
                    except ray.exceptions.RayError as exc:  # its worker died more often than it is retried
                        raise TaskFailed(f"{labels[i]} failed on Ray after {self.RETRIES} retries: {exc}") from exc
                    if progress:
                        progress(weights[i] if weights else 1)
        except BaseException:
            for r in remaining:  # nothing left running behind a failure or an interrupt
                ray.cancel(r, force=True)
            raise
        return out

    def map(self, fn: Callable, tasks: Sequence, progress: Callable[[int], None] | None = None,
            weights: Sequence[int] | None = None) -> list:
        tasks = list(tasks)
        refs = [self._task.remote(fn, t) for t in tasks]
        return self._gather(refs, [f"task {i}" for i in range(len(tasks))], progress, weights)

    def jobs(self, fn: Callable, jobs: Sequence, labels: Sequence[str] | None = None, reporter=None) -> list:
        """Run independent coarse jobs ``fn(job, executor)`` side by side, one Ray task each (their own
        episodes on the same cluster); results in job order. See :meth:`SerialExecutor.jobs`."""
        jobs = list(jobs)
        labels = [f"job {lab}" for lab in (labels or [str(i) for i in range(len(jobs))])]
        refs = [self._job.remote(fn, j, lab) for j, lab in zip(jobs, labels)]
        done = [0]

        def one(n):
            done[0] += n
            if reporter is not None:
                reporter.say(f"{done[0]}/{len(jobs)} jobs done")
        return self._gather(refs, labels, one, None)

    def close(self) -> None:
        if self._owns and self._ray.is_initialized():  # never shut down a cluster this process joined
            self._ray.shutdown()


def make_executor(workers: int | None = None, ray_address: str | None = None):
    """``ray_address`` -> :class:`RayExecutor`; ``workers == 1`` -> serial; else a process pool.

    Raises:
        ValueError: workers < 1; an unreachable Ray cluster.
    """
    if ray_address:
        return RayExecutor(ray_address)
    if workers is not None and workers < 1:
        raise ValueError(f"--workers must be >= 1, got {workers}")
    if workers == 1:
        return SerialExecutor()
    return ProcessExecutor(workers)
