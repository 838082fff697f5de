"""Run directories and resume: a run's settings, and a log of its finished episodes.

A run directory holds ``config.json`` (the settings it was started with: a re-run with other
settings is refused, naming them) and ``episodes.jsonl``, one line per finished episode, keyed by
the task's ``key``, appended and fsync'ed in chunks. A run killed at any point loses at most the
chunk in flight; a line cut by the kill is skipped and that episode runs again. ``sgatwalk
fidelity``, ``table1`` and ``stress`` keep their episodes here; ``optimize`` checkpoints its CMA-ES
state (``experiments.optimize.run``).
"""

from __future__ import annotations

import json
import os

from common.defaults import CONTROL_DT
from common.files import atomic_write_text
from experiments.runtime.progress import Reporter


def check_run_dir(run_dir: str, config: dict, what: str, ignore: tuple = ()) -> None:
    """Check, writing nothing, that ``run_dir`` is new or holds a run with the same settings (those in
    ``ignore`` may differ: e.g. more worlds measured later).

    Raises:
        ValueError: ``run_dir`` holds a ``what`` with other settings (the message names them), or an
            unreadable ``config.json``.
    """
    path = os.path.join(run_dir, "config.json")
    if not os.path.exists(path):
        return
    try:
        with open(path) as f:
            old = json.load(f)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path!r} is not the config of a run ({exc}); use another --out") from None
    diff = sorted(k for k in set(old) | set(config) if k not in ignore and old.get(k) != config.get(k))
    if diff:
        raise ValueError(f"{run_dir!r} holds a {what} with other settings ({', '.join(diff)}); use another --out")


def claim_run_dir(run_dir: str, config: dict, what: str, ignore: tuple = ()) -> None:
    """:func:`check_run_dir`, then write ``config`` to ``run_dir/config.json``.

    Raises:
        ValueError: what :func:`check_run_dir` raises.
    """
    check_run_dir(run_dir, config, what, ignore)
    os.makedirs(run_dir, exist_ok=True)
    atomic_write_text(os.path.join(run_dir, "config.json"), json.dumps(config, indent=1))


def distinct_suffixes(parts: list[list[str]]) -> list[str]:
    """Per path (given as its components), the shortest trailing part, joined with ``/``, that no
    other path of ``parts`` ends in (the whole path where none is shorter)."""
    names = []
    for i, ps in enumerate(parts):
        for k in range(1, len(ps) + 1):
            name = "/".join(ps[-k:])
            if all("/".join(q[-k:]) != name for j, q in enumerate(parts) if j != i):
                break
        names.append(name)
    return names


class EpisodeLog:
    """Episodes of one run directory by key.

    Args:
        run_dir: the run directory (created).
        config: the run's settings as JSON values; written to ``config.json``, or compared with it.
        what: what the run is, for messages (e.g. ``"fidelity run"``).
        ignore: config keys that may differ on a resume (e.g. more worlds measured later).
        reporter: where progress lines go.

    Raises:
        ValueError: ``run_dir`` holds a run with other settings (the message names them).
    """

    #: Episodes per chunk saved at once (a few lock-step batches).
    CHUNK = 150

    def __init__(self, run_dir: str, config: dict, what: str, ignore: tuple = (), reporter: Reporter | None = None):
        claim_run_dir(run_dir, config, what, ignore)
        self.run_dir = run_dir
        self.report = reporter or Reporter.quiet()
        self.path = os.path.join(run_dir, "episodes.jsonl")
        self.done: dict[str, dict] = {}
        if os.path.exists(self.path):
            with open(self.path) as f:
                for line in f:
                    try:
                        r = json.loads(line)
                        self.done[r["key"]] = r
                    except (json.JSONDecodeError, KeyError, TypeError):
                        continue  # a line cut by a kill: that episode runs again

    def __contains__(self, key: str) -> bool:
        return key in self.done

    def __getitem__(self, key: str) -> dict:
        return self.done[key]

    def run(self, ex, tasks: list, desc: str, reporter: Reporter | None = None) -> None:
        """Run the tasks (:class:`experiments.runtime.tasks.EpisodeTask` with a ``key``) that have no
        result yet, in chunks of :attr:`CHUNK` (sent to the workers as lock-step batches); each chunk is
        appended to ``episodes.jsonl`` as it ends. Progress per finished batch (a bar in a terminal,
        lines with an ETA otherwise)."""
        from experiments.runtime.batch import map_episodes  # lazy: loads the engines and torch

        report = reporter or self.report
        todo = [t for t in tasks if t.key not in self.done]
        if not todo:
            report.say(f"{desc}: {len(tasks)} episodes already done")
            return
        t0 = report.elapsed
        report.say(f"{desc}: {len(todo)} episodes ({len(tasks) - len(todo)} resumed)")
        with report.count(len(todo), desc) as update:
            for k in range(0, len(todo), self.CHUNK):
                part = todo[k:k + self.CHUNK]
                res = map_episodes(ex, part, progress=update)
                rows = [{"key": t.key, "fitness": r.fitness, "speed_cm_s": r.speed_cm_s, "fell": bool(r.fell),
                         "seconds": r.steps * CONTROL_DT} for t, r in zip(part, res)]
                for row in rows:
                    self.done[row["key"]] = row
                with open(self.path, "a") as f:
                    f.write("".join(json.dumps(row) + "\n" for row in rows))
                    f.flush()
                    os.fsync(f.fileno())
        report.say(f"{desc}: done in {report.elapsed - t0:.0f} s")


def record_path(path: str, world: str, n_worlds: int) -> str:
    """Where the recording of ``world`` goes: ``{world}`` in ``path`` replaced, or ``_sim``/``_real``
    before the suffix when two worlds share one path."""
    if "{world}" in path:
        return path.format(world=world)
    if n_worlds == 1:
        return path
    root, ext = os.path.splitext(path)
    return f"{root}_{world}{ext or '.parquet'}"



__all__ = ["record_path", "EpisodeLog", "check_run_dir", "claim_run_dir", "distinct_suffixes"]
