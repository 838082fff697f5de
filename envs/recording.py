"""One rollout as a :class:`Recording`, saved and loaded as Parquet; :func:`rollout` makes one.

Parquet schema (one row per control step; all columns float64 unless noted)
-----------------------------------------------------------------------------

Sample timing: row k holds the observation measured at ``t[k]`` and the command issued right
after it, held until ``t[k+1] = t[k] + control_dt``. The first row is the state after reset
(``t = 0``); the observation after the last command is not stored.

==================================  ==========  =========  =============================================
column(s)                           unit        required   meaning
==================================  ==========  =========  =============================================
``t``                               s           yes        time of the sample, strictly increasing
``cmd.<joint>`` (23 actuated)       rad         yes        joint target the controller commanded
``q.<joint>`` (24 hinges)           rad         yes        measured joint position (encoder)
``app.<joint>`` (23 actuated)       rad         no         target actually applied (after grounding);
                                                           equals ``cmd`` when absent
``dq.<joint>`` (24)                 rad/s       no         measured joint velocity
``gyro.x|y|z``                      rad/s       no         torso angular velocity, torso frame
``acc.x|y|z``                       m/s^2       no         accelerometer (specific force), torso frame
``angle.roll|pitch``                rad         no         torso roll/pitch estimate
``fsr.L|R``                         N           no         total normal force under each foot
``cop.Lx|Ly|Rx|Ry``                 m           no         centre of pressure in each sole frame
``gt.base.x|y|z``                   m           no         ground truth: torso origin, world frame
``gt.quat.w|x|y|z``                 --          no         ground truth: torso orientation
``gt.vel.x|y|z``, ``gt.angvel.*``   m/s, rad/s  no         ground truth: torso velocities, world frame
``gt.com.x|y|z``                    m           no         ground truth: whole-body CoM, world frame
``gt.cop.x|y|z``                    m           no         ground truth: CoP on the ground (NaN: none)
==================================  ==========  =========  =============================================

Joint names are NAO names (``LHipYawPitch`` ... ``RAnkleRoll``); the 23 actuated joints omit
``RHipYawPitch``, which follows ``LHipYawPitch``. A column group given in part (e.g. ``gyro.x``
without ``gyro.y``) is an error. ``cmd``, ``app`` and ``q`` must be finite; ``gt.cop`` may be NaN.

Metadata: a JSON object stored under the key ``sgatwalk`` of the Parquet schema metadata.
Required keys: ``robot`` (``"nao"``), ``control_dt`` [s]. Optional: ``schema_version`` (1),
``world`` (``sim``/``real``/``grounded``/any label), ``physics_dt``, ``seed``, ``terrain``,
``profile``, ``effects`` (the episode's drawn effect values), ``params`` (gait parameters),
``fixed_base``, ``fell`` (bool), ``fall_time`` [s], ``fall_reason``, ``source`` (free text).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field

import numpy as np

from robots import ROBOT_NAMES, RobotModel, get_robot, nao_h25
from robots.observation import ObservationLayout
from common.files import atomic_path

SCHEMA_VERSION = 1
META_KEY = b"sgatwalk"
GROUPS: dict[str, tuple[str, ...]] = {
    "gyro": ("gyro.x", "gyro.y", "gyro.z"),
    "acc": ("acc.x", "acc.y", "acc.z"),
    "angle": ("angle.roll", "angle.pitch"),
    "fsr": ("fsr.L", "fsr.R"),
    "cop": ("cop.Lx", "cop.Ly", "cop.Rx", "cop.Ry"),
    "gt.base": ("gt.base.x", "gt.base.y", "gt.base.z"),
    "gt.quat": ("gt.quat.w", "gt.quat.x", "gt.quat.y", "gt.quat.z"),
    "gt.vel": ("gt.vel.x", "gt.vel.y", "gt.vel.z"),
    "gt.angvel": ("gt.angvel.x", "gt.angvel.y", "gt.angvel.z"),
    "gt.com": ("gt.com.x", "gt.com.y", "gt.com.z"),
    "gt.cop": ("gt.cop.x", "gt.cop.y", "gt.cop.z"),
}
_MAY_BE_NAN = ("gt.cop",)


class RecordingError(ValueError):
    """A recording is malformed; the message names the column or key."""


def _joint_groups(robot: RobotModel) -> dict[str, tuple[str, ...]]:
    layout = ObservationLayout(robot)
    return {g: layout.columns(g) for g in ("cmd", "app", "q", "dq")}


@dataclass
class Recording:
    """A rollout: ``columns`` (name -> float64 array of shape (N,)) and ``meta`` (JSON-able dict).

    Use :meth:`group` for (N, k) blocks, e.g. ``rec.group("q")`` -> (N, 24) joint angles.
    Construct from data with :meth:`from_arrays` or load with :meth:`from_parquet`; both validate.
    """

    columns: dict[str, np.ndarray]
    meta: dict = field(default_factory=dict)

    # ---------------------------------------------------------------- access
    def __len__(self) -> int:
        return len(self.columns["t"])

    @property
    def t(self) -> np.ndarray:
        return self.columns["t"]

    @property
    def robot(self) -> RobotModel:
        """The robot named by ``meta["robot"]`` (``nao``, ``g1``, ``talos``; ``robots.get_robot``).

        Raises:
            RecordingError: an unknown robot name.
        """
        name = self.meta.get("robot")
        if name in ("nao", "nao_h25"):  # nao_h25: the name recordings made before carried
            return nao_h25()
        if name not in ROBOT_NAMES:
            raise RecordingError(f"recording is of robot {name!r}; this package models nao, "
                                 f"{', '.join(n for n in ROBOT_NAMES if n != 'nao')}")
        return get_robot(name)

    def has(self, group: str) -> bool:
        """Whether a column group (``"dq"``, ``"gyro"``, ``"gt.base"``, ...) is present."""
        return self._names(group)[0] in self.columns

    def _names(self, group: str) -> tuple[str, ...]:
        jg = _joint_groups(self.robot)
        if group in jg:
            return jg[group]
        if group in GROUPS:
            return GROUPS[group]
        raise KeyError(f"unknown column group {group!r}; known: {', '.join([*jg, *GROUPS])}")

    def group(self, group: str) -> np.ndarray:
        """Columns of ``group`` stacked, shape (N, k). ``"app"`` falls back to ``"cmd"``.

        Raises:
            KeyError: unknown group, or a group absent from this recording.
        """
        if group == "app" and not self.has("app"):
            group = "cmd"
        names = self._names(group)
        if names[0] not in self.columns:
            raise KeyError(f"recording has no {group!r} columns")
        return np.stack([self.columns[n] for n in names], axis=1)

    @property
    def fell(self) -> bool:
        return bool(self.meta.get("fell", False))

    # ---------------------------------------------------------------- construction
    @classmethod
    def from_arrays(cls, meta: dict, t: np.ndarray, **groups: np.ndarray) -> "Recording":
        """Build from (N, k) arrays per group, e.g. ``q=Q, cmd=A, gt_base=P`` (``gt_`` -> ``gt.``)."""
        cols = {"t": np.asarray(t, dtype=np.float64)}
        rec = cls(cols, dict(meta))
        for key, arr in groups.items():
            if arr is None:
                continue
            arr = np.asarray(arr, dtype=np.float64)
            names = rec._names(key.replace("gt_", "gt.", 1))
            if arr.ndim != 2 or arr.shape[1] != len(names):
                raise RecordingError(f"group {key!r} must have shape (N, {len(names)}), got {arr.shape}")
            cols.update({n: arr[:, i].copy() for i, n in enumerate(names)})
        rec.meta.setdefault("schema_version", SCHEMA_VERSION)
        rec.validate()
        return rec

    def validate(self) -> None:
        """Check the schema above.

        Raises:
            RecordingError: naming the missing key, missing/partial/non-numeric column, length
                mismatch, non-finite value (with its row) or non-increasing time.
        """
        for key in ("robot", "control_dt"):
            if key not in self.meta:
                raise RecordingError(f"recording metadata lacks the required key {key!r}")
        robot = self.robot
        try:
            dt = float(self.meta["control_dt"])
        except (TypeError, ValueError):
            raise RecordingError(f"metadata 'control_dt' must be a number of seconds, got {self.meta['control_dt']!r}")
        if not (dt > 0 and np.isfinite(dt)):
            raise RecordingError(f"metadata 'control_dt' must be positive, got {dt}")
        if "t" not in self.columns:
            raise RecordingError("recording lacks the required column 't'")
        n = len(self.columns["t"])
        if n == 0:
            raise RecordingError("recording is empty (0 rows)")
        for name, col in self.columns.items():
            if col.ndim != 1 or len(col) != n:
                raise RecordingError(f"column {name!r} has shape {col.shape}, expected ({n},)")
        jg = _joint_groups(robot)
        missing = [c for g in ("cmd", "q") for c in jg[g] if c not in self.columns]
        if missing:
            raise RecordingError(f"recording lacks required column(s) {', '.join(missing[:8])}"
                                 + (f" and {len(missing) - 8} more" if len(missing) > 8 else ""))
        known = {"t"}
        partial = []
        for g, names in {**jg, **GROUPS}.items():
            present = [c for c in names if c in self.columns]
            if present and len(present) != len(names):
                partial.append(f"{g!r} (missing {', '.join(c for c in names if c not in self.columns)})")
        if partial:
            raise RecordingError(f"column group(s) incomplete: {'; '.join(partial)}")
        for g, names in {**jg, **GROUPS}.items():
            known.update(names)
            present = [c for c in names if c in self.columns]
            if present and g not in _MAY_BE_NAN:
                for c in names:
                    bad = ~np.isfinite(self.columns[c])
                    if bad.any():
                        raise RecordingError(f"column {c!r} has a non-finite value at row {int(np.argmax(bad))}")
        t = self.columns["t"]
        if not np.all(np.isfinite(t)):
            raise RecordingError(f"column 't' has a non-finite value at row {int(np.argmax(~np.isfinite(t)))}")
        if n > 1 and np.any(np.diff(t) <= 0):
            raise RecordingError(f"column 't' is not strictly increasing (row {int(np.argmax(np.diff(t) <= 0)) + 1})")

    # ---------------------------------------------------------------- Parquet
    def to_table(self):
        names = (["t"] if "t" in self.columns else []) + sorted(c for c in self.columns if c != "t")
        import pyarrow as pa  # lazy: a recording is read and written by few commands

        table = pa.table({c: pa.array(self.columns[c], type=pa.float64()) for c in names})
        return table.replace_schema_metadata({META_KEY: json.dumps(self.meta, default=_json_default).encode()})

    def to_parquet(self, path: str | os.PathLike) -> str:
        """Write atomically (temporary file, then rename); returns the path.

        Raises:
            ValueError: ``path`` is a directory, or cannot be written (the message names it); nothing
                is left behind.
        """
        path = os.fspath(path)
        if os.path.isdir(path):
            raise ValueError(f"{path!r} is a directory; give a file name for the recording (e.g. walk.parquet)")
        import pyarrow.parquet as pq  # lazy: see to_table

        try:
            with atomic_path(path, suffix=".parquet") as tmp:
                pq.write_table(self.to_table(), tmp)
        except OSError as exc:
            raise ValueError(f"cannot write the recording to {path!r}: {exc.strerror or exc}") from None
        return path

    @classmethod
    def from_parquet(cls, path: str | os.PathLike) -> "Recording":
        """Load and validate a recording.

        Raises:
            FileNotFoundError: no such file.
            RecordingError: not a Parquet file, no ``sgatwalk`` metadata, or a schema violation.
        """
        import pyarrow as pa  # lazy: see to_table
        import pyarrow.parquet as pq

        path = os.fspath(path)
        if not os.path.exists(path):
            raise FileNotFoundError(f"no recording at {path!r}")
        try:
            table = pq.read_table(path)
        except (pa.ArrowInvalid, OSError) as exc:
            raise RecordingError(f"{path!r} is not a readable Parquet file: {exc}") from None
        md = table.schema.metadata or {}
        if META_KEY not in md:
            raise RecordingError(f"{path!r} has no 'sgatwalk' metadata (robot, control_dt); see envs/recording.py")
        try:
            meta = json.loads(md[META_KEY])
        except json.JSONDecodeError as exc:
            raise RecordingError(f"{path!r}: metadata is not valid JSON ({exc})") from None
        if not isinstance(meta, dict):
            raise RecordingError(f"{path!r}: metadata must be a JSON object")
        cols = {}
        for name in table.column_names:
            col = table.column(name)
            if not (pa.types.is_floating(col.type) or pa.types.is_integer(col.type)):
                raise RecordingError(f"column {name!r} has type {col.type}, expected numbers")
            cols[name] = col.to_numpy(zero_copy_only=False).astype(np.float64)
        rec = cls(cols, meta)
        rec.validate()
        return rec


def _json_default(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    raise TypeError(f"{type(o).__name__} is not JSON serialisable")
