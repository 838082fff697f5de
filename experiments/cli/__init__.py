"""The ``sgatwalk`` command line: one entry point, one module per subcommand.

Each subcommand lives in its own module of this package and defines

* ``register(subparsers) -> argparse.ArgumentParser``: adds the subparser and its options;
* ``run(args)``: turns the options into the experiment's config, runs it and returns its result
  (JSON values or dataclasses).

``main`` prints the result as one JSON object when ``--json`` is given; otherwise the subcommand
prints its own human-readable output. Bad user input is found at the boundary: option types and
ranges by argparse (:mod:`experiments.cli.argtypes`), the rest where a command reads what the user
gave (:func:`experiments.cli.argtypes.user_input`); either is one line on stderr, exit status 2. Any
other exception is a bug and shows as one, with its traceback. The modules here import no physics
engine or torch: ``sgatwalk --help`` answers at once.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import sys

from experiments.cli.argtypes import Parser, UsageError, fail

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
    "experiments.cli.stochasticity",
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


def main(argv: list[str] | None = None) -> int:
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    for stream in (sys.stdout, sys.stderr):  # lines reach a pipe or file as they are printed
        if hasattr(stream, "reconfigure"):
            stream.reconfigure(line_buffering=True)
    parser = build_parser()
    try:  # ranges and paths are checked here (experiments.cli.argtypes): one line, exit 2
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help (0) or a bad option (2, already printed)
        return exc.code if isinstance(exc.code, int) else 2
    from experiments.runtime.executors import limit_blas_threads

    limit_blas_threads()
    try:
        result = args._run(args)
    except UsageError as exc:
        return fail(f"sgatwalk {args.command}", str(exc))
    except KeyboardInterrupt:
        print(f"sgatwalk {args.command}: interrupted", file=sys.stderr)
        return 130
    if args.json:
        from common.files import jsonable

        result = jsonable(result)
        print(json.dumps(result if args.timings else drop_timings(result), allow_nan=False))
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
