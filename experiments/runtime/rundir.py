"""A resumable log of evaluation episodes, shared by ``sgatwalk fidelity`` and ``sgatwalk table1``.

A run directory holds ``config.json`` (the settings it was started with: a re-run with other
settings is refused) and ``episodes.jsonl``, one line per finished episode, keyed by the task's
``key``, appended and fsync'ed in batches. A run killed at any point loses at most the batch in
flight; a line cut by the kill is skipped and that episode runs again.
"""

from __future__ import annotations

import json
import os
import time
from typing import Callable

from common.defaults import CONTROL_DT
from common.files import atomic_write_text

#: Seconds between the progress lines of a run without a terminal.
ETA_EVERY_S = 30.0


class EpisodeLog:
    """Episodes of one run directory by key.

    Args:
        run_dir: the run directory (created).
        config: the run's settings as JSON values; written to ``config.json``, or compared with it.
        what: what the run is, for messages (e.g. ``"fidelity run"``).
        ignore: config keys that may differ on a resume (e.g. more worlds measured later).
        say: progress sink (one line per message).

    Raises:
        ValueError: ``run_dir`` holds a run with other settings (the message names them).
    """

    def __init__(self, run_dir: str, config: dict, what: str, ignore: tuple = (), say: Callable[[str], None] = print):
        self.run_dir, self.say = run_dir, say
        self.path = os.path.join(run_dir, "episodes.jsonl")
        os.makedirs(run_dir, exist_ok=True)
        cfg_path = os.path.join(run_dir, "config.json")
        if os.path.exists(cfg_path):
            with open(cfg_path) as f:
                old = json.load(f)
            diff = sorted(k for k in set(old) | set(config) if k not in ignore and old.get(k) != config.get(k))
            if diff:
                raise ValueError(f"{run_dir!r} holds a {what} with other settings ({', '.join(diff)}); use another --out")
        atomic_write_text(cfg_path, json.dumps(config, indent=1))
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

    def run(self, ex, tasks: list[dict], desc: str, progress: bool = True) -> None:
        """Run the tasks (``experiments.runtime.tasks.run_episode`` dicts with a ``key``) that have no result
        yet, in chunks of 150 (sent to the workers as lock-step batches); each chunk is appended to ``episodes.jsonl`` as it ends.
        Without a terminal a line with the count and an ETA goes to ``say`` every :data:`ETA_EVERY_S`
        seconds, counted as the executor's batches end."""
        from experiments.runtime.batch import MAX_BATCH, map_episodes  # lazy: loads the engines and torch

        todo = [t for t in tasks if t["key"] not in self.done]
        if not todo:
            self.say(f"{desc}: {len(tasks)} episodes already done")
            return
        t0 = time.perf_counter()
        self.say(f"{desc}: {len(todo)} episodes ({len(tasks) - len(todo)} resumed)")
        bar = None
        if progress:
            from tqdm import tqdm  # lazy: tqdm

            bar = tqdm(total=len(todo), desc=desc, leave=False, disable=None)
        lines = _EtaLines(desc, len(todo), self.say, t0) if bar is None or bar.disable else None
        chunk = max(8, 2 * MAX_BATCH)  # lock-step batches (experiments.runtime.batch), saved as each chunk ends
        try:
            for k in range(0, len(todo), chunk):
                part = todo[k:k + chunk]
                res = map_episodes(ex, part, progress=(bar.update if lines is None else lines.update))
                rows = [{"key": t["key"], "fitness": r["fitness"], "speed_cm_s": r["speed_cm_s"], "fell": bool(r["fell"]),
                         "seconds": r["steps"] * CONTROL_DT} for t, r in zip(part, res)]
                for row in rows:
                    self.done[row["key"]] = row
                with open(self.path, "a") as f:
                    f.write("".join(json.dumps(row) + "\n" for row in rows))
                    f.flush()
                    os.fsync(f.fileno())
        finally:
            if bar:
                bar.close()
        self.say(f"{desc}: done in {time.perf_counter() - t0:.0f} s")


class _EtaLines:
    """Progress without a terminal: a line with the count and an ETA every :data:`ETA_EVERY_S` s, counted as
    the executor's batches end (``map_episodes``'s ``progress``), so a chunk of long episodes (the
    real world's) shows its progress too."""

    def __init__(self, desc: str, total: int, say: Callable[[str], None], t0: float):
        self.desc, self.total, self.say, self.t0, self.every = desc, total, say, t0, ETA_EVERY_S
        self.n, self.last = 0, t0

    def update(self, n: int) -> None:
        self.n += n
        now = time.perf_counter()
        if now - self.last > self.every and self.n < self.total:
            self.say(f"{self.desc}: {self.n}/{self.total}, ETA {(now - self.t0) / self.n * (self.total - self.n):.0f} s")
            self.last = now


__all__ = ["ETA_EVERY_S", "EpisodeLog"]
