"""Loading recordings for diagnosis: files or folders of Parquet logs, checked for what replay needs.

A diagnosis reads any recording that follows the schema of :mod:`envs.recording` (ground truth is
optional) and never writes to it: :func:`load_logs` only opens files for reading. A real robot
does not know its torso's true position and velocity: :func:`load_logs` drops the ``gt.*`` columns
unless asked to keep them, and floating-base replays then estimate the base state
(:mod:`sysid.estimate`); :func:`base_state_source` says which of the two a replay of some logs uses.
"""

from __future__ import annotations

import dataclasses
import glob
import os
from dataclasses import dataclass, field

import numpy as np

from envs.recording import Recording, RecordingError
from robots import RobotModel, get_robot

#: Shortest log a replay can use [s] (a few servo time constants plus a 0.1 s window).
MIN_SECONDS = 1.0
#: The ground-truth groups a floating-base replay starts from when a log has all of them.
GT_GROUPS = ("gt.base", "gt.quat", "gt.vel", "gt.angvel")
#: What a report says about the base state of the replays (:func:`base_state_source`).
BASE_ESTIMATED = "estimated from IMU, encoders and foot force sensors (contact-aided, flat ground)"
BASE_GROUND_TRUTH = "ground truth (--use-ground-truth)"
BASE_FIXED = "fixed base"


@dataclass
class Log:
    """One recording reduced to what replay and diagnosis use.

    Attributes:
        name: file stem.  path: source file (None for in-memory).
        t: (N,) sample times [s].  cmd: (N, n) joint targets, n = the robot's joint count (``app``,
            or ``cmd`` when absent; a mimic joint copies its leader) [rad].  q: (N, n) measured
            angles [rad].
        dq: (N, n) measured velocities [rad/s] or None.
        control_dt, physics_dt: [s].  fixed_base: bool.
        imu: dict with ``angle`` (N, 2) [rad], ``gyro`` (N, 3) [rad/s] when recorded.
        fsr: (N, 2) foot forces [N] or None.  gt: dict of the ground-truth groups present
            (:data:`GT_GROUPS`, each (N, 3) or (N, 4) quaternions wxyz; SI units, world frame);
            empty for a real robot's recording and, unless asked, after :func:`load_logs`.
        meta: the recording's metadata (read-only use); ``meta["robot"]`` names the robot
            (:attr:`robot`; ``"nao"`` when absent).
    """

    name: str
    t: np.ndarray
    cmd: np.ndarray
    q: np.ndarray
    dq: np.ndarray | None
    control_dt: float
    physics_dt: float
    fixed_base: bool
    path: str | None = None
    imu: dict = field(default_factory=dict)
    fsr: np.ndarray | None = None
    gt: dict = field(default_factory=dict)
    meta: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.t)

    @property
    def substeps(self) -> int:
        return int(round(self.control_dt / self.physics_dt))

    @property
    def seconds(self) -> float:
        return len(self.t) * self.control_dt

    @property
    def robot_name(self) -> str:
        """The robot's name, ``meta["robot"]`` (``"nao"``, ``"g1"``, ``"talos"``; ``"nao"`` when absent)."""
        name = str(self.meta.get("robot") or "nao")
        return "nao" if name == "nao_h25" else name  # nao_h25: the name recordings made before carried

    @property
    def robot(self) -> RobotModel:
        """The robot the log is of (``robots.get_robot(robot_name)``, cached there; read-only).

        Raises:
            KeyError: an unknown robot name.
        """
        return get_robot(self.robot_name)


def from_recording(rec: Recording, name: str = "log", path: str | None = None, *, ground_truth: bool = True) -> Log:
    """Convert a validated :class:`Recording` into a :class:`Log`.

    ``ground_truth``: keep the recording's ``gt.base``, ``gt.quat``, ``gt.vel`` and ``gt.angvel``
    groups in :attr:`Log.gt` (False: ``Log.gt`` is empty, as for a real robot's recording).

    Raises:
        RecordingError: robot is not one of ``robots.ROBOT_NAMES`` (``nao``, ``g1``, ``talos``);
            shorter than :data:`MIN_SECONDS`; sample times not on the ``control_dt`` grid;
            ``control_dt`` not a multiple of ``physics_dt``.
    """
    robot = rec.robot  # raises RecordingError on a mismatched robot
    dt = float(rec.meta["control_dt"])
    pdt = float(rec.meta.get("physics_dt") or 0.001)
    ratio = dt / pdt
    if abs(ratio - round(ratio)) > 1e-6 or round(ratio) < 1:
        raise RecordingError(f"{name}: control_dt {dt} s is not a multiple of physics_dt {pdt} s")
    n = len(rec)
    if n * dt < MIN_SECONDS:
        raise RecordingError(f"{name}: recording is too short ({n} rows, {n * dt:.2f} s; need >= {MIN_SECONDS} s)")
    t = rec.t
    if n > 1 and np.max(np.abs(np.diff(t) - dt)) > 1e-3 * dt + 1e-9:
        k = int(np.argmax(np.abs(np.diff(t) - dt) > 1e-3 * dt + 1e-9))
        raise RecordingError(f"{name}: sample times are not on the control_dt grid of {dt} s (row {k + 1}); "
                             "resample the log first")
    cmd = robot.expand_action(rec.group("app"))
    q = rec.group("q")
    dq = rec.group("dq") if rec.has("dq") else None
    if dq is not None and not np.all(np.isfinite(dq)):
        raise RecordingError(f"{name}: column group 'dq' has non-finite values")
    imu = {}
    for g in ("angle", "gyro"):
        if rec.has(g):
            imu[g] = rec.group(g)
    gt = {g: rec.group(g) for g in GT_GROUPS if ground_truth and rec.has(g)}
    gt = {k: v for k, v in gt.items() if np.all(np.isfinite(v))}
    fixed = rec.meta.get("fixed_base")
    if fixed is None:  # infer: a hanging robot has no foot forces
        fixed = bool(rec.has("fsr") and np.all(rec.group("fsr") < 1e-6))
    meta = dict(rec.meta)
    meta["robot"] = robot.name  # canonical ("nao_h25" -> "nao"): logs of one robot compare equal
    return Log(name=name, t=t.copy(), cmd=cmd, q=q, dq=dq, control_dt=dt, physics_dt=pdt, fixed_base=bool(fixed),
               path=path, imu=imu, fsr=rec.group("fsr") if rec.has("fsr") else None, gt=gt, meta=meta)


def find_files(inputs: list[str] | str) -> list[str]:
    """Expand folders (``*.parquet`` inside, sorted) and files into a list of paths.

    Raises:
        FileNotFoundError: a path does not exist, or a folder holds no ``.parquet`` file.
    """
    if isinstance(inputs, str):
        inputs = [inputs]
    out = []
    for p in inputs:
        for item in p.split(",") if "," in p and not os.path.exists(p) else [p]:
            if os.path.isdir(item):
                found = sorted(glob.glob(os.path.join(item, "*.parquet")))
                if not found:
                    raise FileNotFoundError(f"no .parquet recordings in folder {item!r}")
                out.extend(found)
            elif os.path.exists(item):
                out.append(item)
            else:
                raise FileNotFoundError(f"no recording or folder at {item!r}")
    return out


def load_logs(inputs: list[str] | str, *, use_ground_truth: bool = False) -> list[Log]:
    """Load and check every recording of ``inputs`` (files and/or folders); read-only.

    ``use_ground_truth``: keep the recordings' ``gt.*`` base-state columns (``sgatwalk diagnose
    --use-ground-truth``); by default they are dropped (``Log.gt`` empty), so floating-base replays
    start from the state estimated from IMU, encoders and foot forces, as on a real robot.

    Raises:
        FileNotFoundError: missing path or empty folder.
        RecordingError: a malformed recording (missing column, NaN, wrong robot, too short, ...),
            named by file; or logs that disagree on robot, ``control_dt``, ``physics_dt`` or base mode;
            or ``use_ground_truth`` with floating-base recordings that lack the ``gt.*`` columns.
    """
    paths = find_files(inputs)
    logs = []
    for p in paths:
        name = os.path.splitext(os.path.basename(p))[0]
        try:
            rec = Recording.from_parquet(p)
            logs.append(from_recording(rec, name=name, path=p, ground_truth=use_ground_truth))
        except RecordingError as exc:
            msg = str(exc)
            raise RecordingError(msg if p in msg or name in msg else f"{p}: {msg}") from None
    check_consistent(logs)
    if use_ground_truth and logs and not logs[0].fixed_base and not all(has_ground_truth(lg) for lg in logs):
        raise RecordingError("--use-ground-truth: the recordings have no gt.base, gt.quat, gt.vel and gt.angvel "
                             "columns (a real robot's recordings do not); diagnose without it")
    return logs


def has_ground_truth(log: Log) -> bool:
    """Whether ``log`` carries every ground-truth group a replay starts from (:data:`GT_GROUPS`)."""
    return all(g in log.gt for g in GT_GROUPS)


def without_ground_truth(logs: list[Log]) -> list[Log]:
    """Shallow copies of ``logs`` with ``gt`` empty (the arrays are shared, never written)."""
    return [dataclasses.replace(lg, gt={}) if lg.gt else lg for lg in logs]


def base_state_source(logs: list[Log]) -> str:
    """Where a replay of ``logs`` takes the floating base's state from: :data:`BASE_FIXED` for
    fixed-base logs, :data:`BASE_GROUND_TRUTH` when every log carries the ``gt.*`` groups, else
    :data:`BASE_ESTIMATED` (:func:`sysid.estimate.base_state`).

    Raises:
        ValueError: no logs; some floating-base logs with ground truth and some without (a replay
            would mix the two; drop it from all with :func:`without_ground_truth`).
    """
    if not logs:
        raise ValueError("no logs")
    if logs[0].fixed_base:
        return BASE_FIXED
    have = [has_ground_truth(lg) for lg in logs]
    if all(have):
        return BASE_GROUND_TRUTH
    if any(have):
        missing = next(lg.name for lg, h in zip(logs, have) if not h)
        raise ValueError(f"{missing}: no gt.base/gt.quat/gt.vel/gt.angvel ground truth while other logs have it; "
                         "replay all logs from ground truth or none")
    return BASE_ESTIMATED


def check_consistent(logs: list[Log]) -> None:
    """All logs share robot, control_dt, physics_dt and base mode.

    Raises:
        RecordingError: naming the first log that differs.
    """
    if not logs:
        raise RecordingError("no recordings given")
    ref = logs[0]
    for lg in logs[1:]:
        for attr in ("robot_name", "control_dt", "physics_dt", "fixed_base"):
            if getattr(lg, attr) != getattr(ref, attr):
                raise RecordingError(f"{lg.name}: {attr} = {getattr(lg, attr)} differs from {ref.name}'s "
                                     f"{getattr(ref, attr)}; diagnose logs of one setup together")


def split_by_trajectory(logs: list[Log], heldout_fraction: float = 0.3) -> tuple[list[int], list[int], str]:
    """Indices of training and held-out logs, split by whole trajectory (every ~3rd log held out).

    With a single log, it is cut into a first 60 % (train) and last 40 % (held out) and the
    returned note says so (held-out is then not a different trajectory).

    Returns:
        (train indices, held-out indices, note).
    """
    n = len(logs)
    if n == 1:
        return [0], [0], "single log: the last 40 % of it is held out (record >= 2 logs for a trajectory split)"
    n_hold = max(1, int(round(heldout_fraction * n)))
    step = n / n_hold
    hold = sorted({min(n - 1, int((k + 1) * step) - 1) for k in range(n_hold)})
    train = [i for i in range(n) if i not in hold]
    return train, hold, f"{len(train)} training log(s), {len(hold)} held-out log(s), split by trajectory"
