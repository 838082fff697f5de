"""The ``sgatwalk`` command line: one entry point, one module per subcommand.

Each subcommand lives in its own module under ``experiments/`` that defines

* ``register(subparsers) -> argparse.ArgumentParser``: adds the subparser and its options;
* ``run(args) -> dict``: does the work and returns a JSON-serialisable result.

``main`` prints ``run``'s result as one JSON object when ``--json`` is given; otherwise the
subcommand prints its own human-readable output. Errors that come from bad user input
(:class:`UsageError`, ``ValueError``, ``FileNotFoundError``) are printed as one clear line on
stderr with exit status 2, never as a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import json
import math
import os
import sys
from typing import Any

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


def _jsonable(obj: Any) -> Any:
    """Convert NumPy scalars/arrays and non-finite floats into strict JSON values."""
    import numpy as np

    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return _jsonable(obj.item())
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


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
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        result = args._run(args)
    except (UsageError, ValueError, FileNotFoundError, KeyError) as exc:
        msg = exc.args[0] if exc.args else exc
        print(f"sgatwalk {args.command}: error: {msg}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"sgatwalk {args.command}: interrupted", file=sys.stderr)
        return 130
    if args.json:
        print(json.dumps(_jsonable(result), allow_nan=False))
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
