"""Recordings to show: checks, entity-path labels, and finding recordings in files and directories."""

from __future__ import annotations

import json
import os
import re

import pyarrow.parquet as pq

from envs.recording import META_KEY, Recording, RecordingError
from experiments.viz.style import WORLD_COLORS


def check_recording(rec: Recording, label: str = "recording") -> None:
    """Refuse what cannot be shown.

    Any robot of :data:`robots.ROBOT_NAMES` can be drawn (``meta["robot"]``: ``nao``, ``g1``,
    ``talos``); the recording's joint columns must be that robot's.

    Raises:
        RecordingError: a recording of an unknown robot, one without any joint angle column
            (``q.<joint>``) of its robot (e.g. a NAO log labelled ``talos``), a robot whose model cannot
            be loaded (``example-robot-data`` missing), an empty recording, or one that fails
            :meth:`envs.Recording.validate`; the message starts with ``label``.
    """
    if not isinstance(rec, Recording):
        raise RecordingError(f"{label}: expected an envs.Recording, got {type(rec).__name__}")
    name = rec.meta.get("robot")
    try:
        robot = rec.robot
    except RecordingError as exc:  # unknown name: "recording is of robot ...; this package models ..."
        raise RecordingError(f"{label}: {exc}") from None
    except ModuleNotFoundError as exc:
        raise RecordingError(f"{label}: recording is of robot {name!r}, whose model cannot be loaded: {exc}") from None
    mismatch = _robot_mismatch(name, robot, rec.columns)
    if mismatch:
        raise RecordingError(f"{label}: {mismatch}")
    if "t" not in rec.columns or len(rec.columns["t"]) == 0:
        raise RecordingError(f"{label}: recording is empty (0 rows)")
    try:
        rec.validate()
    except RecordingError as exc:
        raise RecordingError(f"{label}: {exc}") from None


def _robot_mismatch(name, robot, columns) -> str | None:
    """Why columns ``columns`` (names) are not a recording of ``robot`` (named ``name`` in the
    metadata): none of its ``q.<joint>`` columns; None when at least one is there."""
    if any(f"q.{j}" in columns for j in robot.joint_names):
        return None
    return (f"recording is of robot {name!r} but has none of its joint angle columns (q.{robot.joint_names[0]}, "
            "...); is it a recording of another robot?")


def _mismatch_in_file(path: str) -> str | None:
    """:func:`_robot_mismatch` of a Parquet recording read cheaply (schema only); None when the
    file, its metadata or its robot cannot be read (the loader names that problem)."""
    try:
        schema = pq.read_schema(path)
        meta = json.loads((schema.metadata or {})[META_KEY])
        robot = Recording({}, meta).robot
    except Exception:  # noqa: BLE001 - anything unreadable: Recording.from_parquet's message stands
        return None
    return _robot_mismatch(meta.get("robot"), robot, set(schema.names))


_PART = re.compile(r"[^A-Za-z0-9_.\-]+")


def sanitize_label(label: str) -> str:
    """An entity-path-safe label: parts separated by '/', each of [A-Za-z0-9_.-] (others -> '_').

    Raises:
        ValueError: an empty label.
    """
    parts = [_PART.sub("_", p).strip("_") or "_" for p in str(label).strip("/").split("/") if p.strip()]
    if not parts:
        raise ValueError(f"empty recording label {label!r}")
    return "/".join(parts)


def _is_recording_file(path: str) -> bool:
    """Whether a Parquet file carries ``sgatwalk`` recording metadata (cheap: schema only)."""
    try:
        md = pq.read_schema(path).metadata or {}
    except Exception:  # noqa: BLE001 - not Parquet at all: let from_parquet name the problem
        return True
    return META_KEY in md


def find_recordings(paths: list[str]) -> tuple[dict[str, Recording], list[str]]:
    """Load recordings from Parquet files and directories and label them by world.

    A directory (e.g. an ``optimize`` run directory) contributes every ``*.parquet`` below it,
    recursively, that carries recording metadata; other Parquet files there (``evals.parquet``)
    are skipped. Labels: the metadata ``world`` when a world has one recording, else
    ``<world>/<relative path without .parquet>`` for each of them. Order: sim, real, grounded,
    then other worlds alphabetically; within a world by path.

    Returns:
        (label -> recording, skipped paths).

    Raises:
        FileNotFoundError: a path that does not exist; a directory without recordings.
        RecordingError: a file given explicitly that is not a valid recording, a malformed
            recording in a directory, a recording of an unknown robot or with another robot's
            columns, an empty recording (the message names the file).
    """
    found: list[tuple[str, str]] = []  # (file, name used for the label)
    skipped: list[str] = []
    for p in paths:
        p = os.fspath(p)
        if os.path.isdir(p):
            files = []
            for dirpath, dirnames, filenames in os.walk(p):
                dirnames.sort()
                files += [os.path.join(dirpath, f) for f in sorted(filenames) if f.endswith(".parquet")]
            recs = [f for f in files if _is_recording_file(f)]
            skipped += [f for f in files if f not in recs]
            if not recs:
                raise FileNotFoundError(f"no recordings (*.parquet with sgatwalk metadata) under {p!r}")
            found += [(f, os.path.relpath(f, p)[: -len(".parquet")]) for f in recs]
        elif os.path.exists(p):
            found.append((p, os.path.splitext(os.path.basename(p))[0]))
        else:
            raise FileNotFoundError(f"no recording at {p!r}")
    loaded: list[tuple[str, str, Recording]] = []
    for f, name in found:
        try:
            rec = Recording.from_parquet(f)
        except RecordingError as exc:
            msg = _mismatch_in_file(f) or str(exc)  # another robot's columns: say so, not "lacks q.*"
            raise RecordingError(msg if f in msg else f"{f}: {msg}") from None
        check_recording(rec, f)
        loaded.append((f, name, rec))
    rank = {w: i for i, w in enumerate(WORLD_COLORS)}  # sim, real, grounded first: left to right
    loaded.sort(key=lambda x: (rank.get(str(x[2].meta.get("world")), len(rank)), str(x[2].meta.get("world")), x[1]))
    count: dict[str, int] = {}
    for _, _, rec in loaded:
        w = str(rec.meta.get("world", "recording"))
        count[w] = count.get(w, 0) + 1
    out: dict[str, Recording] = {}
    for f, name, rec in loaded:
        w = sanitize_label(str(rec.meta.get("world", "recording")))
        lab = w if count[str(rec.meta.get("world", "recording"))] == 1 else f"{w}/{sanitize_label(name)}"
        base, k = lab, 2
        while lab in out:
            lab = f"{base}_{k}"
            k += 1
        out[lab] = rec
    return out, skipped
