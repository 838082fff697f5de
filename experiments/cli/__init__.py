"""The ``sgatwalk`` command line: one entry point, one module per subcommand.

Each subcommand lives in its own module under ``experiments/`` that defines

* ``register(subparsers) -> argparse.ArgumentParser``: adds the subparser and its options;
* ``run(args) -> dict``: does the work and returns a JSON-serialisable result.

``main`` prints ``run``'s result as one JSON object when ``--json`` is given; otherwise the
subcommand prints its own human-readable output. Errors that come from bad user input
(:class:`UsageError`, ``ValueError``, ``KeyError``, and ``OSError`` such as a missing, unwritable or
existing file) are printed as one clear line on stderr, naming the file, with exit status 2, never as
a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import sys

from experiments.cli.argtypes import Parser, fail
from common.files import jsonable

# Subcommand modules, in the order ``sgatwalk --help`` lists them.
COMMANDS: list[str] = [
    "experiments.cli.optimize",
    "experiments.cli.walk",
    "experiments.cli.stand",
    "experiments.cli.cliff",
    "experiments.cli.gym",
    "experiments.cli.excite",
    "experiments.cli.diagnose",
    "experiments.cli.visualize",
    "experiments.cli.stress",
    "experiments.cli.fidelity",
    "experiments.cli.compare",
    "experiments.cli.table1",
]


#: Result keys that hold wall-clock measurements: dropped from ``--json`` output unless ``--timings``.
TIMING_KEYS = frozenset({"wall_s", "elapsed_s", "realtime_factor", "log_seconds", "job_wall_s", "cpu_s", "phases_s"})


def drop_timings(obj):
    """``obj`` without :data:`TIMING_KEYS` at any depth (the result of a run, as JSON values)."""
    if isinstance(obj, dict):
        return {k: drop_timings(v) for k, v in obj.items() if k not in TIMING_KEYS}
    if isinstance(obj, list):
        return [drop_timings(v) for v in obj]
    return obj


class UsageError(ValueError):
    """Bad user input: printed as one line, exit status 2."""


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="sgatwalk",
        description="Sim-to-real transfer testbed for humanoid walking (SGAT, ZMP walk engine, "
        "MuJoCo sim vs PyBullet real).",
    )
    sub = parser.add_subparsers(dest="command", metavar="<command>")
    sub.required = True
    for name in COMMANDS:
        try:
            mod = importlib.import_module(name)
        except ModuleNotFoundError as exc:  # a command whose module is not there yet
            if exc.name == name:
                continue
            raise
        p = mod.register(sub)
        p.add_argument("--json", action="store_true", help="print the result as one JSON object")
        p.add_argument("--timings", action="store_true",
                       help="keep wall-clock times (wall_s, ...) in the --json output (left out by default, so that "
                            "two identical runs print identical JSON)")
        p.set_defaults(_run=mod.run)
    return parser


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


def main(argv: list[str] | None = None) -> int:
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    for stream in (sys.stdout, sys.stderr):  # lines reach a pipe or file as they are printed
        if hasattr(stream, "reconfigure"):
            stream.reconfigure(line_buffering=True)
    parser = build_parser()  # imports numpy: its BLAS is loaded now
    limit_blas_threads()
    try:  # ranges and paths are checked here (experiments.cli.argtypes): one line, exit 2
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help (0) or a bad option (2, already printed)
        return exc.code if isinstance(exc.code, int) else 2
    try:
        result = args._run(args)
    except (UsageError, ValueError, KeyError, OSError) as exc:
        if isinstance(exc, OSError) and exc.strerror:  # e.g. [Errno 13] on an unwritable --out: name the file
            msg = f"{exc.strerror}: {exc.filename!r}" if exc.filename else exc.strerror
        else:
            msg = exc.args[0] if exc.args else exc
        return fail(f"sgatwalk {args.command}", str(msg))
    except KeyboardInterrupt:
        print(f"sgatwalk {args.command}: interrupted", file=sys.stderr)
        return 130
    if args.json:
        result = jsonable(result)
        print(json.dumps(result if args.timings else drop_timings(result), allow_nan=False))
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
