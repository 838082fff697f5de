"""Argument types of the ``sgatwalk`` command line: every number has a range, every path is checked
before any work starts.

argparse calls these on the text of an option (``type=`` of ``ArgumentParser.add_argument``,
https://docs.python.org/3/library/argparse.html#type); a bad value raises
``argparse.ArgumentTypeError``, which :class:`Parser` prints as one line naming the flag, with exit
status 2. So ``--seconds -5``, ``--seconds nan``, ``--seed 1e12`` or ``--record /some/dir/`` fail in
milliseconds, before a walk of several seconds, and leave nothing behind.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from contextlib import contextmanager

#: Largest seed numpy.random.SeedSequence takes as one 32-bit word.
SEED_MAX = 2**32 - 1


class UsageError(ValueError):
    """Bad user input found after parsing (a malformed θ file, a world the robot lacks, a run directory
    of another run): printed as one line, exit status 2."""


@contextmanager
def user_input():
    """Treat what the block raises as the user's input being bad: ``ValueError``, ``KeyError`` and a
    missing file become a :class:`UsageError` (one line, exit 2). Wrap only the code that reads what
    the user gave (building a config, loading a file or a run directory): an error anywhere else is a
    bug and keeps its traceback."""
    try:
        yield
    except UsageError:
        raise
    except (ValueError, KeyError, FileNotFoundError, NotADirectoryError, IsADirectoryError) as exc:
        msg = exc.args[0] if exc.args else str(exc)
        if isinstance(exc, OSError) and exc.strerror and exc.filename:
            msg = f"{exc.strerror}: {exc.filename!r}"
        raise UsageError(str(msg)) from exc


class Parser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose errors are one line, ``<prog>: error: <message>``, exit status 2
    (argparse's default prints the whole usage first)."""

    def error(self, message: str):  # noqa: D102 - argparse's hook
        self.exit(2, f"{self.prog}: error: {' '.join(str(message).split())}\n")


class Number:
    """An int or float option in ``[lo, hi]`` (``None``: unbounded on that side); ``open_lo``
    excludes ``lo`` itself (e.g. a duration: > 0). NaN and infinities are always refused."""

    def __init__(self, kind: type, lo: float | None = None, hi: float | None = None, *, open_lo: bool = False,
                 unit: str = ""):
        if kind not in (int, float):
            raise TypeError(f"kind must be int or float, got {kind!r}")
        self.kind, self.lo, self.hi, self.open_lo, self.unit = kind, lo, hi, open_lo, unit
        self.__name__ = kind.__name__  # argparse names the type in its messages

    def range_text(self) -> str:
        u = f" {self.unit}" if self.unit else ""
        f = (lambda v: f"{int(v)}") if self.kind is int else (lambda v: f"{v:g}")  # noqa: E731
        if self.lo is not None and self.hi is not None:
            return f"in {'(' if self.open_lo else '['}{f(self.lo)}, {f(self.hi)}]{u}"
        if self.lo is not None:
            return f"{'>' if self.open_lo else '>='} {f(self.lo)}{u}"
        return f"<= {f(self.hi)}{u}" if self.hi is not None else "finite"

    def __call__(self, text: str):
        try:
            v = float(text) if self.kind is float else int(text, 10)
        except (TypeError, ValueError):
            raise argparse.ArgumentTypeError(
                f"expected {'an integer' if self.kind is int else 'a number'} {self.range_text()}, got {text!r}") from None
        if self.kind is float and not math.isfinite(v):
            raise argparse.ArgumentTypeError(f"expected a finite number {self.range_text()}, got {text!r}")
        if (self.lo is not None and (v < self.lo or (self.open_lo and v == self.lo))) or \
                (self.hi is not None and v > self.hi):
            raise argparse.ArgumentTypeError(f"must be {self.range_text()}, got {text}")
        return v

    def __repr__(self) -> str:
        return f"Number({self.kind.__name__}, {self.range_text()})"


def count(lo: int = 1, hi: int = 1_000_000) -> Number:
    """A count (episodes, trials, workers, ...) in [lo, hi]."""
    return Number(int, lo, hi)


def real(lo: float | None = None, hi: float | None = None, *, open_lo: bool = False, unit: str = "") -> Number:
    """A finite float in [lo, hi] (``open_lo``: lo excluded)."""
    return Number(float, lo, hi, open_lo=open_lo, unit=unit)


#: ``--seed``: a non-negative integer numpy.random.SeedSequence takes as one word.
seed = Number(int, 0, SEED_MAX)
#: ``--seconds``: an episode or log duration, (0, 1 h].
seconds = Number(float, 0.0, 3600.0, open_lo=True, unit="s")
#: ``--workers``: worker processes.
workers = Number(int, 1, 256)
#: A blend or probability in [0, 1].
fraction = Number(float, 0.0, 1.0)


def levels(text: str) -> tuple[float, ...]:
    """Per-step stochasticity levels (``--levels``): a comma list or ``start:stop:count`` of numbers >= 0,
    or ``none`` (no level: e.g. a study of Table I runs only)."""
    from common.parse import parse_values

    if text.strip().lower() == "none":
        return ()
    try:
        vals = parse_values(text, "levels", hint="expected a comma list (e.g. 0,1,2,3) or start:stop:count")
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    if any(v < 0 for v in vals):
        raise argparse.ArgumentTypeError(f"levels must be >= 0, got {min(vals):g}")
    return tuple(vals)


def worlds(text: str) -> tuple[str, ...]:
    """Training worlds as a comma list (``--methods``): their canonical names
    (:func:`experiments.runtime.worlds.parse_worlds`)."""
    from experiments.runtime.worlds import parse_worlds  # imports no engine

    try:
        return tuple(s.name for s in parse_worlds(text))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def world(text: str) -> str:
    """One training world (``--worlds`` items): its canonical name (:func:`experiments.runtime.worlds.parse_world`)."""
    from experiments.runtime.worlds import parse_world  # imports no engine

    try:
        return parse_world(text).name
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _nearest_existing(path: str) -> str:
    p = os.path.abspath(path)
    while not os.path.exists(p):
        parent = os.path.dirname(p)
        if parent == p:
            break
        p = parent
    return p


def _check_creatable(path: str, what: str) -> None:
    base = _nearest_existing(path)
    if not os.path.isdir(base):
        raise argparse.ArgumentTypeError(f"cannot create {what} {path!r}: {base!r} is not a directory")
    if not os.access(base, os.W_OK | os.X_OK):
        raise argparse.ArgumentTypeError(f"cannot create {what} {path!r}: {base!r} is not writable")


def out_file(text: str) -> str:
    """A file the command will write: not a directory, and creatable (the parent, or its nearest
    existing ancestor, is a writable directory). Nothing is created here."""
    if not text:
        raise argparse.ArgumentTypeError("empty file name")
    if os.path.isdir(text) or text.endswith(os.sep):
        raise argparse.ArgumentTypeError(f"{text!r} is a directory; give a file name")
    if os.path.exists(text):
        if not os.access(text, os.W_OK):
            raise argparse.ArgumentTypeError(f"{text!r} is not writable")
        return text
    _check_creatable(text, "file")
    return text


def out_dir(text: str) -> str:
    """A directory the command will write into: an existing directory, or creatable."""
    if not text:
        raise argparse.ArgumentTypeError("empty directory name")
    if os.path.exists(text):
        if not os.path.isdir(text):
            raise argparse.ArgumentTypeError(f"{text!r} exists and is not a directory")
        if not os.access(text, os.W_OK | os.X_OK):
            raise argparse.ArgumentTypeError(f"{text!r} is not writable")
        return text
    _check_creatable(text, "directory")
    return text


def in_file(text: str) -> str:
    """A file the command reads: it exists and is a readable file."""
    if not os.path.exists(text):
        raise argparse.ArgumentTypeError(f"no such file: {text!r}")
    if os.path.isdir(text):
        raise argparse.ArgumentTypeError(f"{text!r} is a directory; give a file")
    if not os.access(text, os.R_OK):
        raise argparse.ArgumentTypeError(f"{text!r} is not readable")
    return text


def in_dir(text: str) -> str:
    """A folder the command reads: it exists and is a directory."""
    if not os.path.isdir(text):
        raise argparse.ArgumentTypeError(f"no such directory: {text!r}")
    return text


def in_path(text: str) -> str:
    """A file or a folder the command reads: it exists."""
    if not os.path.exists(text):
        raise argparse.ArgumentTypeError(f"no such file or directory: {text!r}")
    if not os.access(text, os.R_OK):
        raise argparse.ArgumentTypeError(f"{text!r} is not readable")
    return text


def profile(text: str) -> str:
    """A real-world effect profile name (``envs.effects.PROFILES``)."""
    from envs.effects import PROFILES  # imports no engine

    if text not in PROFILES:
        raise argparse.ArgumentTypeError(f"unknown profile {text!r}; choose from {', '.join(PROFILES)}")
    return text


def add_profile(parser: argparse.ArgumentParser) -> None:
    """Add ``--profile`` (default real) and ``--stochasticity`` (default 0): the real world's effect profile and
    per-step randomness (``envs.effects.Stochasticity``)."""
    parser.add_argument("--profile", type=profile, help="real-world effect profile: real (default), none, real-flat "
                        "(real on flat ground) or real-ground (its uneven ground alone)")
    parser.add_argument("--stochasticity", type=real(0.0, 10.0, unit="level"), default=0.0, metavar="LEVEL",
                        help="the real world's per-step randomness: servo torque noise per control step, foot "
                             "friction and contact softness per touchdown (0: none, the default; 1-3: docs/concepts/worlds.md)")


def add_executor(parser: argparse.ArgumentParser) -> None:
    """Add ``--workers`` and ``--ray-address``: where the episodes run (a local process pool by default)."""
    parser.add_argument("--workers", type=workers, help="worker processes (default: one per core; 1 = serial)")
    parser.add_argument("--ray-address", metavar="ADDRESS",
                        help="run on a Ray cluster instead (auto, or host:port of its head; docs/cluster.md)")


def add_robot(parser: argparse.ArgumentParser) -> None:
    """Add ``--robot nao|g1|talos`` (default nao): the robot both worlds and the walk engine use
    (``robots.get_robot``; g1 and talos come from the installed example-robot-data)."""
    from robots import ROBOT_NAMES  # lazy: argtypes is imported by every command's parser

    parser.add_argument("--robot", choices=ROBOT_NAMES, default="nao",
                        help="robot: nao (the NAO-like H25, default), g1 (Unitree G1) or talos (PAL Talos), "
                             "the last two from example-robot-data")


def fail(prog: str, message: str) -> int:
    """Print ``<prog>: error: <message>`` as one line on stderr; returns 2 (the exit status)."""
    print(f"{prog}: error: {' '.join(str(message).split())}", file=sys.stderr, flush=True)
    return 2


__all__ = ["Number", "Parser", "UsageError", "user_input", "add_executor", "levels", "add_profile", "add_robot", "count", "fail", "fraction", "in_dir", "in_file",
           "in_path", "out_dir", "out_file", "profile", "real", "seconds", "seed", "workers", "world", "worlds"]
