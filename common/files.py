"""File output: atomic writes (a temporary file in the same folder, fsync, then ``os.replace``),
strict JSON values, and the wall time of resumable runs.

A reader (or a resumed run after a kill) sees either the old file or the new one, never a torn
one; a failed write leaves no temporary file behind.
"""

from __future__ import annotations

import contextlib
import math
import os
import tempfile
from pathlib import Path
from typing import Any, Iterator

_UMASK = os.umask(0o022)
os.umask(_UMASK)


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (parents created, fsync before the rename); returns the path."""
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
    return Path(path)


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    return atomic_write_bytes(path, text.encode("utf-8"))


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, suffix: str = ".tmp") -> Iterator[str]:
    """A temporary path beside ``path`` for writers that take a file name (``torch.save``,
    ``pyarrow.parquet.write_table``, ``Figure.savefig``); renamed onto ``path`` when the block ends,
    removed if it raises. ``suffix`` keeps the extension writers read the format from (``".png"``).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix, dir=path.parent)
    os.close(fd)
    try:
        yield tmp
        os.chmod(tmp, 0o666 & ~_UMASK)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


def atomic_write_json(path: str | os.PathLike, obj: Any, indent: int | None = 1) -> Path:
    """Write ``obj`` as strict JSON (:func:`jsonable`) to ``path`` atomically, with a final newline."""
    import json

    return atomic_write_text(path, json.dumps(jsonable(obj), indent=indent) + "\n")


def jsonable(obj: Any, private: bool = True) -> Any:
    """``obj`` as strict JSON values: NumPy scalars and arrays to Python, dataclasses to dicts of their
    fields, non-finite floats to None.

    ``private=False`` drops dict keys that start with ``_`` (internal fields of a report).
    """
    import dataclasses

    import numpy as np

    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        obj = {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}
    if isinstance(obj, dict):
        return {str(k): jsonable(v, private) for k, v in obj.items() if private or not str(k).startswith("_")}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v, private) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist(), private)
    if isinstance(obj, np.generic):
        return jsonable(obj.item(), private)
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


class WallClock:
    """Wall time a resumable run has spent in all, across the invocations that resumed it.

    ``timing.json`` in the run directory holds the seconds of the invocations so far; :meth:`total`
    adds this one's. A run directory from before ``timing.json`` existed starts from the ``wall_s``
    of its result file (``legacy``), the time its one uninterrupted invocation took.
    """

    def __init__(self, run_dir: str | os.PathLike, legacy: str | os.PathLike | None = None):
        import json
        import time

        self.path = Path(run_dir) / "timing.json"
        self.t0 = time.perf_counter()
        self.before = 0.0
        try:
            if self.path.exists():
                self.before = float(json.loads(self.path.read_text())["wall_s"])
            elif legacy is not None and Path(legacy).exists():
                self.before = float(json.loads(Path(legacy).read_text()).get("wall_s") or 0.0)
        except (ValueError, KeyError, TypeError):
            self.before = 0.0

    def total(self) -> float:
        """Seconds of every invocation so far, this one included (up to now)."""
        import time

        return self.before + time.perf_counter() - self.t0

    def save(self) -> float:
        """Write the total so far to ``timing.json``; returns it."""
        import json

        t = self.total()
        atomic_write_text(self.path, json.dumps({"wall_s": t}))
        return t
