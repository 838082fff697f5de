"""Where a run's messages and progress go: one object every experiment is given.

A :class:`Reporter` prints one line per message on stderr, flushed at once and stamped with the
elapsed time (``[optimize 73.2 s] hybrid step 1: ...``), and counts long work: in a terminal as a
tqdm bar, without one (a pipe, a log file, CI) as a line with the count and an ETA every
:data:`ETA_EVERY_S` seconds. Children share the clock and add their name (``[table1 12.0 s] seed 2:
...``). ``Reporter.quiet()`` swallows everything (tests, ``--json`` runs that want a clean stderr).
"""

from __future__ import annotations

import sys
import time
from contextlib import contextmanager
from typing import Callable, Iterator

#: Seconds between the progress lines of a count without a terminal.
ETA_EVERY_S = 30.0


class Reporter:
    """Messages and progress of one run.

    Args:
        name: the run's name, printed with each line (e.g. ``"fidelity"``); "" prints the time only.
        stream: where lines go (default ``sys.stderr``); ``None`` with ``quiet``.
        bars: tqdm bars in a terminal (default: when ``stream`` is one).
        every_s: seconds between the ETA lines of a count without a terminal.
    """

    def __init__(self, name: str = "", *, stream=None, bars: bool | None = None, every_s: float = ETA_EVERY_S,
                 _t0: float | None = None, _prefix: str = "", _quiet: bool = False):
        self.name, self.every_s = name, float(every_s)
        self.stream = None if _quiet else (stream or sys.stderr)
        self.bars = bool(self.stream is not None and getattr(self.stream, "isatty", lambda: False)()) if bars is None \
            else bool(bars)
        self.t0 = time.perf_counter() if _t0 is None else _t0
        self._prefix = _prefix

    @classmethod
    def quiet(cls) -> Reporter:
        """A reporter that prints nothing."""
        return cls(_quiet=True)

    @classmethod
    def to(cls, say: Callable[[str], None] | None, name: str = "") -> Reporter:
        """A reporter whose lines go to a callable (``None``: a quiet one)."""
        if say is None:
            return cls.quiet()

        class _Lines:
            def write(self, text: str) -> None:
                if text.strip():
                    say(text.rstrip("\n"))

            def flush(self) -> None:
                pass

        return cls(name, stream=_Lines(), bars=False)

    def child(self, name: str) -> Reporter:
        """A reporter for a part of this run: the same clock and stream, ``name`` before its lines."""
        r = Reporter(self.name, stream=self.stream, bars=self.bars, every_s=self.every_s, _t0=self.t0,
                     _prefix=f"{self._prefix}{name} ", _quiet=self.stream is None)
        return r

    @property
    def elapsed(self) -> float:
        """Seconds since the run's reporter was made."""
        return time.perf_counter() - self.t0

    def say(self, msg: str) -> None:
        """One line: ``[name elapsed s] prefix msg``."""
        if self.stream is None:
            return
        head = f"[{self.name} {self.elapsed:7.1f} s]" if self.name else f"[{self.elapsed:7.1f} s]"
        print(f"{head} {self._prefix}{msg}", file=self.stream, flush=True)

    @contextmanager
    def count(self, total: int, desc: str, *, initial: int = 0) -> Iterator[Callable[[int], None]]:
        """Count ``total`` units of work: yields ``update(n)``, called as n more are done. A tqdm bar in
        a terminal; otherwise a line with the count and an ETA every :attr:`every_s` seconds."""
        if self.stream is None or total <= 0:
            yield lambda n: None
            return
        if self.bars:
            from tqdm import tqdm  # lazy: tqdm

            bar = tqdm(total=total, initial=initial, desc=f"{self._prefix}{desc}", leave=False, file=self.stream)
            try:
                yield bar.update
            finally:
                bar.close()
            return
        state = {"n": initial, "last": time.perf_counter(), "t0": time.perf_counter()}

        def update(n: int) -> None:
            state["n"] += n
            now = time.perf_counter()
            if now - state["last"] >= self.every_s and state["n"] < total:
                done = state["n"] - initial
                eta = (now - state["t0"]) / max(done, 1) * (total - state["n"])
                self.say(f"{desc}: {state['n']}/{total}, ETA {eta:.0f} s")
                state["last"] = now

        yield update


__all__ = ["ETA_EVERY_S", "Reporter"]
