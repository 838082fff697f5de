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

from experiments.files import jsonable

# Subcommand modules, in the order ``sgatwalk --help`` lists them.
COMMANDS: list[str] = [
    "experiments.cmd_optimize",
    "experiments.cmd_walk",
    "experiments.cmd_stand",
    "experiments.cmd_cliff",
    "experiments.cmd_gym",
    "experiments.cmd_excite",
    "experiments.cmd_diagnose",
    "experiments.cmd_visualize",
    "experiments.cmd_stress",
    "experiments.cmd_fidelity",
    "experiments.cmd_table1",
]


class UsageError(ValueError):
    """Bad user input: printed as one line, exit status 2."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
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
        p.set_defaults(_run=mod.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    for stream in (sys.stdout, sys.stderr):  # lines reach a pipe or file as they are printed
        if hasattr(stream, "reconfigure"):
            stream.reconfigure(line_buffering=True)
    parser = build_parser()
    args = parser.parse_args(argv)
    seed = getattr(args, "seed", None)
    if seed is not None and seed < 0:  # every command's seeds feed numpy.random.SeedSequence: non-negative
        print(f"sgatwalk {args.command}: error: --seed must be >= 0, got {seed}", file=sys.stderr)
        return 2
    try:
        result = args._run(args)
    except (UsageError, ValueError, KeyError, OSError) as exc:
        if isinstance(exc, OSError) and exc.strerror:  # e.g. [Errno 13] on an unwritable --out: name the file
            msg = f"{exc.strerror}: {exc.filename!r}" if exc.filename else exc.strerror
        else:
            msg = exc.args[0] if exc.args else exc
        print(f"sgatwalk {args.command}: error: {' '.join(str(msg).split())}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"sgatwalk {args.command}: interrupted", file=sys.stderr)
        return 130
    if args.json:
        print(json.dumps(jsonable(result), allow_nan=False))
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
