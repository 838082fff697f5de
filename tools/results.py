"""Save a command's result under ``docs/results/``, stamped with the commit, CPU model and date.

    python -m tools.results save NAME -- sgatwalk optimize
    python -m tools.results save bench-walk -- python benchmarks/bench_walk.py
    python -m tools.results stamp            # what a result made now would be stamped with

The command is run as a user would run it (a subprocess; ``--json`` is appended, and ``--timings``
for ``sgatwalk`` commands), its stdout must be one JSON object, and ``docs/results/NAME.json``
becomes ``{"command", "result", "stamp"}``: ``stamp`` holds the commit (and whether the working tree
had uncommitted changes), the CPU model and core count, the date, the Python version and the
1-minute load average before and after. Progress lines go to stderr as the command prints them. The
docs are rendered from these files (``python -m tools.docs``); this tool imports nothing of the
project.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import shlex
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "docs" / "results"


def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo``, else ``platform.processor()``)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _git(*args: str) -> str:
    try:
        return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return ""


def stamp() -> dict:
    """What produced a result now: commit, uncommitted changes, CPU model and cores, date, Python."""
    return {"commit": _git("rev-parse", "--short=12", "HEAD") or "unknown",
            "dirty": bool(_git("status", "--porcelain", "--untracked-files=no")),
            "cpu": cpu_model(), "cores": os.cpu_count(), "date": datetime.date.today().isoformat(),
            "python": platform.python_version(), "load": round(os.getloadavg()[0], 2)}


def run_command(argv: list[str]) -> dict:
    """Run ``argv`` with ``--json`` (and ``--timings`` for sgatwalk) and return the JSON object it printed.

    Raises:
        SystemExit: the command failed or printed no JSON object (its exit status and stderr shown).
    """
    cmd = list(argv)
    exe = os.path.basename(cmd[0])
    if exe == "sgatwalk":  # the project's console script, from the environment this tool runs in
        cmd[0] = str(Path(sys.executable).with_name("sgatwalk"))
        cmd += ["--json", "--timings"]
    else:
        if exe.startswith("python"):
            cmd[0] = sys.executable
        cmd.append("--json")
    proc = subprocess.run(cmd, cwd=ROOT, stdout=subprocess.PIPE, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"tools.results: {' '.join(map(shlex.quote, argv))} failed with exit status {proc.returncode}")
    try:
        out = json.loads(proc.stdout.strip().splitlines()[-1])
    except (json.JSONDecodeError, IndexError):
        raise SystemExit(f"tools.results: {' '.join(map(shlex.quote, argv))} printed no JSON object on its last line") from None
    if not isinstance(out, dict):
        raise SystemExit("tools.results: the command's JSON is not an object")
    return out


def finite(value):
    """``value`` with every NaN or infinite float replaced by None (JSON null), recursively: a command's
    JSON may hold NaN (e.g. a correlation over constant data), which strict JSON cannot."""
    if isinstance(value, float):
        return value if value == value and value not in (float("inf"), float("-inf")) else None
    if isinstance(value, dict):
        return {k: finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite(v) for v in value]
    return value


def save(name: str, argv: list[str]) -> Path:
    """Run the command and write ``docs/results/<name>.json`` atomically; return its path."""
    if not name.replace("-", "").replace("_", "").isalnum():
        raise SystemExit(f"tools.results: a result name is letters, digits, - and _, got {name!r}")
    before = stamp()
    result = run_command(argv)
    doc = {"command": " ".join(map(shlex.quote, argv)), "result": finite(result),
           "stamp": {**before, "load_after": round(os.getloadavg()[0], 2)}}
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / f"{name}.json"
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(doc, indent=1, allow_nan=False) + "\n")
    os.replace(tmp, path)
    return path


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tools.results", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="verb", required=True)
    s = sub.add_parser("save", help="run a command and save its JSON result under docs/results/")
    s.add_argument("name", help="the result's name (docs/results/NAME.json)")
    s.add_argument("command", nargs=argparse.REMAINDER, help="-- then the command, as a user types it")
    sub.add_parser("stamp", help="print the stamp a result made now would carry")
    a = ap.parse_args(argv)
    if a.verb == "stamp":
        print(json.dumps(stamp()))
        return 0
    cmd = a.command[1:] if a.command[:1] == ["--"] else a.command
    if not cmd:
        ap.error("give the command after --")
    print(save(a.name, cmd))
    return 0


if __name__ == "__main__":
    sys.exit(main())
