"""Terrain stress tests: how far does each gait hold up as the ground gets rougher?

For every gait (policy), every terrain level and every trial, one walking episode (the paper's
7.5 s, :func:`experiments.runtime.fitness.run_walk`) runs through an executor (serial, process pool or
Ray; :mod:`experiments.runtime.executors`). The comparison is *paired*:

* trial ``j`` of run seed ``s`` has one terrain seed and one episode seed,
  ``numpy.random.SeedSequence([s, j]).generate_state(2)``, shared by all policies **and all
  levels**: the terrain of trial ``j`` at every level is the same field scaled to the level's
  amplitude (the generators scale a fixed random shape to its peak), and the real world draws the
  same effects and sensor noise. Levels and policies therefore differ only in what they name
  (common random numbers), which keeps the fall-rate curves smooth and the policy comparison fair;
* the terrain is a :class:`terrain.Heightfield` built here from ``(kind, terrain seed, level)``
  and handed to the world as ``reset(options={"terrain": hf})``, so a level is the same physical
  ground in the MuJoCo sim and in the PyBullet "real" world. In the real world the profile's own
  ``terrain_amplitude`` is then unused; its other effects are drawn from the episode seed.

``--sweep EFFECT=lo:hi:n`` replaces the terrain axis by one real-world effect
(:data:`envs.effects.EFFECTS`, e.g. ``latency_s``, ``foot_friction``, ``mass_scale``): the level is
the effect's value, fixed for every episode (``RealProfile.with_effect``), on either the profile's
own random terrain (default) or ``--terrain KIND --amplitude A`` (one value).

Outputs in the run directory (all written atomically):

==================  ===========================================================================
``stress.json``     the run's settings; a re-run in the same directory must agree on world,
                    axis, terrain kind, profile, seed and episode length
``trials.csv``      one row per (policy, level, trial) episode (:data:`TRIAL_COLUMNS`); rewritten
                    after every chunk of episodes, so an interrupted sweep resumes where it
                    stopped (rows are matched on policy label, gait hash, level and trial)
``trials.parquet``  the same rows (written at the end)
``summary.csv``     the table: per policy and level, fall rate with its 95 % Wilson interval,
                    speed mean ± std of the trials that did not fall, mean distance before a fall
``stress.png``      fall rate and speed against level, one line per policy, with bands
``rerun/*.rrd``     with ``rerun=True``: the worst trial of each policy at each level (first fall,
                    else slowest), one file per policy (Rerun, :mod:`experiments.viz`)
==================  ===========================================================================

The 95 % interval of a fall rate k/n is Wilson's score interval (E. B. Wilson, JASA 1927;
the same as ``scipy.stats.binomtest(k, n).proportion_ci(method="wilson")``).
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from common.defaults import EPISODE_SECONDS
from common.files import WallClock
from common.files import atomic_write_bytes as _atomic_write_bytes
from common.parse import parse_values
from experiments.runtime.executors import make_executor
from experiments.runtime.progress import Reporter
from experiments.runtime.seeds import derive_seeds
from experiments.runtime.stats import wilson_interval
from experiments.runtime.tasks import EpisodeResult, EpisodeTask
from robots import get_robot
from walk_engine import params_for

#: Terrain kinds a stress run sweeps (``terrain.TERRAINS`` without "flat": amplitude 0 is flat).
TERRAIN_KINDS = ("lumpy", "fractal", "steps", "slope")
#: Columns of ``trials.csv`` / ``trials.parquet``, one row per episode.
TRIAL_COLUMNS = [
    "policy", "theta_hash", "level", "trial", "terrain_seed", "episode_seed", "world", "terrain",
    "fell", "fall_reason", "fall_time_s", "speed_cm_s", "distance_m", "drift_m", "fitness", "steps",
    "wall_s",
]
#: Columns of the table (``summary.csv``); the first eight are the ``--json`` row keys.
SUMMARY_COLUMNS = [
    "policy", "level", "trials", "falls", "fall_rate", "fall_rate_ci95", "speed_cm_s_mean",
    "speed_cm_s_std", "speed_n", "distance_before_fall_m_mean", "fall_time_s_mean",
    "distance_m_mean",
]
#: Columns of ``summary.csv`` (the interval split into two columns).
SUMMARY_CSV_COLUMNS = [c for c in SUMMARY_COLUMNS if c != "fall_rate_ci95"]
SUMMARY_CSV_COLUMNS[5:5] = ["fall_rate_ci95_low", "fall_rate_ci95_high"]
#: Settings that must agree for a run directory to be resumed.
_INVARIANTS = ("world", "axis", "terrain", "amplitude", "profile", "seed", "seconds")
#: Units of the effects (``envs.effects`` table), for labels.
EFFECT_UNITS = {
    "kp_scale": "-", "kd_scale": "-", "latency_s": "s", "backlash_rad": "rad", "coulomb_friction_nm": "N m",
    "viscous_damping": "N m s/rad", "torque_limit_scale": "-", "mass_scale": "-", "foot_friction": "-",
    "encoder_bias_rad": "rad", "encoder_noise_rad": "rad", "gyro_bias": "rad/s", "gyro_noise": "rad/s",
    "accel_noise": "m/s^2", "angle_noise_rad": "rad", "terrain_amplitude": "m",
}


# --------------------------------------------------------------------------------------------
# Input
# --------------------------------------------------------------------------------------------


def parse_levels(spec: str | float | Sequence[float], what: str = "--amplitude") -> list[float]:
    """Parse a level list (:func:`common.parse.parse_values`): ``start:stop:count``, a comma list, a
    single number, or a sequence of numbers; rounded to 12 decimals, duplicates removed.

    Raises:
        ValueError: malformed text, an empty range, a non-finite value (naming ``what``).
    """
    return parse_values(spec, what)


#: The sweep axis of the real world's per-step randomness (``envs.effects.Stochasticity``), beside its effects.
STOCHASTICITY = "stochasticity"


def parse_sweep(spec: str) -> tuple[str, list[float]]:
    """Parse ``--sweep EFFECT=lo:hi:n`` (or ``EFFECT=v1,v2,...``); ``EFFECT`` is a real-world effect or
    ``stochasticity`` (levels of per-step randomness).

    Raises:
        ValueError: no ``=``, an unknown effect (the message lists the known ones), bad values.
    """
    from envs.effects import EFFECTS  # lazy: loads the engines

    if "=" not in str(spec):
        raise ValueError(f"--sweep: expected EFFECT=lo:hi:n (e.g. latency_s=0:0.04:5), got {spec!r}")
    name, values = str(spec).split("=", 1)
    name = name.strip()
    if name not in EFFECTS and name != STOCHASTICITY:
        raise ValueError(f"--sweep: unknown effect {name!r}; known: {', '.join(EFFECTS)}, {STOCHASTICITY}")
    return name, parse_levels(values, f"--sweep {name}")


@dataclass(frozen=True)
class Policy:
    """One gait under test: a label, its 16 parameters (SI, ``GaitParams`` order) and a hash."""

    label: str
    theta: tuple[float, ...]
    source: str

    @property
    def theta_hash(self) -> str:
        """First 12 hex digits of the SHA-1 of the parameters' JSON (exact float repr)."""
        return hashlib.sha1(json.dumps([float(v) for v in self.theta]).encode()).hexdigest()[:12]


def load_policies(paths: Sequence[str | os.PathLike | None] | None, robot: str = "nao") -> list[Policy]:
    """Gait parameter files -> policies labelled by file stem (θ0 as ``theta0`` for None or an
    empty list); repeated labels get ``_2``, ``_3`` ... The files are read as ``robot``'s gait
    parameters (``walk_engine.params_for``).

    Raises:
        FileNotFoundError: a file that does not exist; ValueError: unreadable or invalid JSON
        (messages from ``GaitParams.load`` name the file and the problem).
    """
    out: list[Policy] = []
    seen: dict[str, int] = {}
    P = params_for(get_robot(robot))
    for p in (list(paths) if paths else [None]):
        if p is None:
            params, label, src = P.initial(), "theta0", "θ0"
        else:
            if os.path.isdir(p):
                raise ValueError(f"cannot read gait parameters from {os.fspath(p)!r}: it is a directory")
            params, label, src = P.load(p), Path(p).stem, os.fspath(p)
        seen[label] = seen.get(label, 0) + 1
        if seen[label] > 1:
            label = f"{label}_{seen[label]}"
        out.append(Policy(label, tuple(float(v) for v in params.to_array()), src))
    return out


def trial_seeds(seed: int, trial: int) -> tuple[int, int]:
    """(terrain seed, episode seed) of trial ``trial`` of a run with seed ``seed``.

    The same for every policy and every level: the pairing of the comparison."""
    a, b = derive_seeds(int(seed), int(trial), n=2)
    return a, b


@dataclass
class StressConfig:
    """A validated stress run.

    Attributes:
        policies: the gaits.
        world: ``"real"`` (PyBullet) or ``"sim"`` (MuJoCo).
        axis: ``"terrain"`` (levels are terrain amplitudes [m], or grades for ``slope``) or the
            name of a real-world effect (levels are its values).
        terrain: terrain kind (:data:`TERRAIN_KINDS`); None in a sweep = the profile's own
            random lumpy field.
        amplitude: in a sweep with a terrain kind: the one amplitude [m] (grade for slope).
        levels: the level values, in order.
        trials: episodes per policy and level.
        seed: run seed (terrain and episode seeds, :func:`trial_seeds`).
        profile: real-world effect profile (``RealProfile.to_dict()``); None in the sim.
        seconds: episode length [s].
        stochasticity: the real world's per-step randomness level (``envs.effects.Stochasticity``) of
            every level (a sweep over ``stochasticity`` sets it per level instead).
        robot: ``robots.get_robot`` name (default the NAO).
    """

    policies: list[Policy]
    world: str
    axis: str
    terrain: str | None
    amplitude: float | None
    levels: list[float]
    trials: int
    seed: int
    profile: dict | None
    seconds: float = EPISODE_SECONDS

    robot: str = "nao"
    stochasticity: float = 0.0

    def invariants(self) -> dict:
        d = {k: getattr(self, k) for k in _INVARIANTS}
        if self.robot != "nao":  # runs saved without a robot (the NAO) keep their invariants
            d["robot"] = self.robot
        if self.stochasticity:  # likewise runs without per-step randomness
            d["stochasticity"] = self.stochasticity
        return d

    def to_dict(self) -> dict:
        d = self.invariants()
        d.update(levels=self.levels, trials=self.trials,
                 policies=[{"label": p.label, "source": p.source, "theta_hash": p.theta_hash,
                            "theta": list(p.theta)} for p in self.policies])
        return d

    @property
    def level_name(self) -> str:
        """Axis label with display unit, e.g. ``lumpy amplitude [cm]``."""
        if self.axis == STOCHASTICITY:
            return "per-step stochasticity [level]"
        if self.axis != "terrain":
            return f"{self.axis} [{EFFECT_UNITS.get(self.axis, '-')}]"
        return "slope grade [%]" if self.terrain == "slope" else f"{self.terrain} amplitude [cm]"

    def level_display(self, v: float) -> float:
        """A level in display units (cm for amplitudes, % for grades, the effect's own unit)."""
        return 100.0 * v if self.axis == "terrain" else v


def make_config(params: Sequence[str | os.PathLike | None] | None = None, *, world: str = "real",
                terrain: str | None = "lumpy", amplitude: str | float | Sequence[float] | None = None,
                trials: int = 20, seed: int = 0, profile: str | dict | None = None, sweep: str | None = None,
                seconds: float = EPISODE_SECONDS, robot: str = "nao", stochasticity: float = 0.0) -> StressConfig:
    """Validate the inputs of a stress run (bad input raises before any episode runs).

    Args:
        params: gait parameter JSON files (None or empty: θ0).
        world: ``"real"`` or ``"sim"``.
        terrain: terrain kind; in a sweep None means the profile's own terrain.
        amplitude: the terrain levels (:func:`parse_levels`, default 0:0.04:9); in a sweep with a terrain kind, one
            value (default 0.02 m).
        trials: episodes per policy and level (>= 1).
        seed: run seed.
        profile: real-world profile name or dict (default ``"real"``); not allowed in the sim.
        sweep: ``EFFECT=lo:hi:n`` (:func:`parse_sweep`): sweep a real-world effect instead of terrain.
        seconds: episode length [s].
        robot: ``robots.get_robot`` name; its "real" profile is scaled to its actuators.
        stochasticity: the real world's per-step randomness level (``envs.effects.Stochasticity``).

    Raises:
        ValueError or FileNotFoundError naming what is wrong: unknown world/terrain/profile/effect,
        an empty or negative level range, trials < 1, a missing or invalid params file, a sweep in
        the sim, an effect value outside its physical domain.
    """
    from envs.effects import get_profile  # lazy: loads the engines

    if world not in ("real", "sim"):
        raise ValueError(f"unknown world {world!r}; choose real or sim")
    if terrain is not None and terrain not in TERRAIN_KINDS:
        hint = " (flat ground is amplitude 0 of any kind)" if terrain == "flat" else ""
        raise ValueError(f"unknown terrain {terrain!r}; choose one of {', '.join(TERRAIN_KINDS)}{hint}")
    if isinstance(trials, bool) or int(trials) != trials or trials < 1:
        raise ValueError(f"--trials must be a positive integer, got {trials!r}")
    if not (seconds > 0 and math.isfinite(seconds)):
        raise ValueError(f"--seconds must be a positive number, got {seconds}")
    if world == "sim" and profile is not None:
        raise ValueError("--profile applies to the real world only (use --world real)")
    if not (math.isfinite(stochasticity) and stochasticity >= 0):
        raise ValueError(f"--stochasticity must be a number >= 0, got {stochasticity}")
    if world == "sim" and stochasticity:
        raise ValueError("--stochasticity applies to the real world only (use --world real)")
    robot_model = get_robot(robot)
    prof = get_profile(profile or "real", robot_model) if world == "real" else None

    if sweep is None:
        if terrain is None:
            raise ValueError("give a terrain kind (lumpy, fractal, steps, slope) or --sweep EFFECT=lo:hi:n")
        levels = parse_levels("0:0.04:9" if amplitude is None else amplitude)
        bad = [v for v in levels if v < 0]
        if bad:
            raise ValueError(f"--amplitude: terrain levels must be >= 0, got {bad[0]:g}")
        axis, amp = "terrain", None
    else:
        if world != "real":
            raise ValueError("--sweep varies a real-world effect: use --world real")
        axis, levels = parse_sweep(sweep)
        if axis == STOCHASTICITY:
            if stochasticity:
                raise ValueError("--stochasticity with --sweep stochasticity=...: give the levels once")
            bad = [v for v in levels if v < 0]
            if bad:
                raise ValueError(f"--sweep stochasticity: levels must be >= 0, got {bad[0]:g}")
        else:
            for v in levels:  # each value must be a valid fixed range of the effect
                prof.with_effect(axis, v)
        amp = None
        if terrain is None and amplitude is not None:
            raise ValueError("--amplitude with --sweep needs --terrain (without it the sweep walks on the profile's "
                             "own random terrain)")
        if terrain is not None:
            vals = parse_levels(0.02 if amplitude is None else amplitude)
            if len(vals) != 1 or vals[0] < 0:
                raise ValueError(f"--amplitude: a sweep over {axis} takes one terrain amplitude >= 0, got {amplitude!r}")
            amp = vals[0]
    policies = load_policies(params, robot)
    return StressConfig(policies=policies, world=world, axis=axis, terrain=terrain, amplitude=amp,
                        levels=levels, trials=int(trials), seed=int(seed),
                        profile=prof.to_dict() if prof is not None else None, seconds=float(seconds), robot=robot,
                        stochasticity=float(stochasticity))


@dataclass(frozen=True)
class Trial:
    """One planned stress episode: which policy, level and trial it is, and its episode task.

    Attributes:
        policy, theta_hash: the gait's label and hash; level: the level's value; trial: its index.
        terrain_seed, episode_seed: the trial's seeds (:func:`trial_seeds`).
        task: the :class:`experiments.runtime.tasks.EpisodeTask` it walks.
    """

    policy: str
    theta_hash: str
    level: float
    trial: int
    terrain_seed: int
    episode_seed: int
    task: EpisodeTask

    @property
    def key(self) -> tuple:
        """Identity of the episode in ``trials.csv``: (policy label, gait hash, level, trial)."""
        return (self.policy, self.theta_hash, self.level, self.trial)


def plan_tasks(cfg: StressConfig) -> list[Trial]:
    """One :class:`Trial` per (level, trial, policy), in that order (level-major): a terrain level is
    the trial's field of that kind at the level's amplitude, laid down at reset; an effect level is
    the real profile with that effect fixed (``RealProfile.with_effect``)."""
    from envs.effects import RealProfile  # imports no engine

    out = []
    for level in cfg.levels:
        stochastic = cfg.stochasticity
        if cfg.axis == "terrain":
            profile, amp = cfg.profile, level
        elif cfg.axis == STOCHASTICITY:
            profile, amp, stochastic = cfg.profile, cfg.amplitude, level
        else:
            profile = RealProfile.from_dict(cfg.profile).with_effect(cfg.axis, level).to_dict()
            amp = cfg.amplitude
        for j in range(cfg.trials):
            ts, es = trial_seeds(cfg.seed, j)
            terr = None if cfg.terrain is None else (cfg.terrain, ts, float(amp))
            for p in cfg.policies:
                task = EpisodeTask(cfg.world, p.theta, es, cfg.seconds, robot=cfg.robot,
                                   profile=profile if profile is not None else "real", terrain=terr,
                                   stochasticity=stochastic)
                out.append(Trial(p.label, p.theta_hash, level, j, ts, es, task))
    return out


def trial_row(trial: Trial, res: EpisodeResult) -> dict:
    """The :data:`TRIAL_COLUMNS` row of one finished trial."""
    return {"policy": trial.policy, "theta_hash": trial.theta_hash, "level": float(trial.level),
            "trial": int(trial.trial), "terrain_seed": int(trial.terrain_seed), "episode_seed": int(trial.episode_seed),
            "world": trial.task.world, "terrain": res.terrain, "fell": bool(res.fell), "fall_reason": res.fall_reason,
            "fall_time_s": res.fall_time_s, "speed_cm_s": float(res.speed_cm_s), "distance_m": float(res.distance_m),
            "drift_m": float(res.drift_m), "fitness": float(res.fitness), "steps": int(res.steps), "wall_s": res.wall_s}


# --------------------------------------------------------------------------------------------
# Statistics
# --------------------------------------------------------------------------------------------


def _key(r: dict) -> tuple:
    """Identity of an episode: (policy label, gait hash, level, trial)."""
    return (r["policy"], r["theta_hash"], r["level"], r["trial"])


def _mean(x) -> float:
    return float(np.mean(x)) if len(x) else math.nan


def summarize(rows: Sequence[dict], cfg: StressConfig) -> list[dict]:
    """The table: one row per policy and level (policy order, then level order) over the rows of
    the planned trials. Keys :data:`SUMMARY_COLUMNS`; speeds [cm/s] over trials that did not fall
    (std with ddof=1, nan below 2 trials), distances [m], ``fall_rate_ci95`` = [low, high]."""
    index = {_key(r): r for r in rows}
    table = []
    for p in cfg.policies:
        for level in cfg.levels:
            rs = [index[k] for k in ((p.label, p.theta_hash, level, j) for j in range(cfg.trials)) if k in index]
            n = len(rs)
            fell = [r for r in rs if r["fell"]]
            ok = np.array([r["speed_cm_s"] for r in rs if not r["fell"]], dtype=float)
            k = len(fell)
            table.append({
                "policy": p.label, "level": level, "trials": n, "falls": k,
                "fall_rate": k / n if n else math.nan,
                "fall_rate_ci95": list(wilson_interval(k, n)),
                "speed_cm_s_mean": _mean(ok),
                "speed_cm_s_std": float(np.std(ok, ddof=1)) if len(ok) > 1 else math.nan,
                "speed_n": int(len(ok)),
                "distance_before_fall_m_mean": _mean([r["distance_m"] for r in fell]),
                "fall_time_s_mean": _mean([r["fall_time_s"] for r in fell]),
                "distance_m_mean": _mean([r["distance_m"] for r in rs]),
            })
    return table


def worst_trials(rows: Sequence[dict], cfg: StressConfig) -> dict[tuple[str, float], dict]:
    """The worst trial per (policy label, level): the earliest fall, else the slowest walk."""
    index = {_key(r): r for r in rows}
    out = {}
    for p in cfg.policies:
        for level in cfg.levels:
            rs = [index[k] for k in ((p.label, p.theta_hash, level, j) for j in range(cfg.trials)) if k in index]
            if rs:
                out[(p.label, level)] = min(rs, key=lambda r: (not r["fell"], r["fall_time_s"] or 0.0,
                                                               r["speed_cm_s"], r["trial"]))
    return out


# --------------------------------------------------------------------------------------------
# Files
# --------------------------------------------------------------------------------------------


def _cell(v) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return ""
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, (list, tuple)):
        return ";".join(_cell(x) for x in v)
    return str(v)


def write_csv(rows: Sequence[dict], columns: Sequence[str], path: Path) -> None:
    """Rows as CSV (floats as exact ``repr``, None/nan as empty), atomically."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(columns)
    for r in rows:
        w.writerow([_cell(r.get(c)) for c in columns])
    _atomic_write_bytes(path, buf.getvalue().encode())


_INT = {"trial", "terrain_seed", "episode_seed", "steps"}
_FLOAT = {"level", "fall_time_s", "speed_cm_s", "distance_m", "drift_m", "fitness", "wall_s"}


def read_trials(path: Path) -> list[dict]:
    """Rows of a ``trials.csv`` written by this module (types restored).

    Raises:
        ValueError: the file lacks columns of :data:`TRIAL_COLUMNS` or holds malformed values.
    """
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        missing = set(TRIAL_COLUMNS) - set(reader.fieldnames or [])
        if missing:
            raise ValueError(f"{path}: not a stress trials file (missing columns {', '.join(sorted(missing))})")
        rows = []
        for i, raw in enumerate(reader, start=2):
            try:
                r: dict[str, Any] = {}
                for c in TRIAL_COLUMNS:
                    v = raw[c]
                    if c in _INT:
                        r[c] = int(v)
                    elif c in _FLOAT:
                        r[c] = float(v) if v != "" else None
                    elif c == "fell":
                        if v not in ("True", "False"):
                            raise ValueError(f"fell={v!r}")
                        r[c] = v == "True"
                    else:
                        r[c] = v if v != "" else None
                rows.append(r)
            except (TypeError, ValueError) as exc:
                raise ValueError(f"{path}, line {i}: malformed row ({exc})") from None
    return rows


def write_parquet(rows: Sequence[dict], path: Path) -> None:
    """The trial rows as Parquet (one column per :data:`TRIAL_COLUMNS`), atomically."""
    import pyarrow as pa  # lazy: pyarrow
    import pyarrow.parquet as pq  # lazy: pyarrow

    types = {c: pa.int64() for c in _INT} | {c: pa.float64() for c in _FLOAT} | {"fell": pa.bool_()}
    table = pa.table({c: pa.array([r.get(c) for r in rows], type=types.get(c, pa.string())) for c in TRIAL_COLUMNS})
    buf = pa.BufferOutputStream()
    pq.write_table(table, buf)
    _atomic_write_bytes(path, buf.getvalue().to_pybytes())


def plot_stress(table: Sequence[dict], cfg: StressConfig, path: Path, title: str | None = None) -> None:
    """Fall rate (95 % Wilson band) and speed of non-fallers (± std band) against the level, one
    line per policy, written as a PNG."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # lazy: matplotlib
    from matplotlib.figure import Figure  # lazy: matplotlib

    fig = Figure(figsize=(7.5, 7.0))
    FigureCanvasAgg(fig)
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    colors = ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown", "tab:pink",
              "tab:gray", "tab:olive", "tab:cyan"]
    markers = "osD^v<>ph*"
    order = np.argsort(cfg.levels, kind="stable")
    x = np.array([cfg.level_display(cfg.levels[i]) for i in order])
    for i, p in enumerate(cfg.policies):
        rows = {r["level"]: r for r in table if r["policy"] == p.label}
        get = lambda k: np.array([rows[cfg.levels[j]][k] for j in order], dtype=float)  # noqa: E731
        c, m = colors[i % len(colors)], markers[i % len(markers)]
        lo = np.array([rows[cfg.levels[j]]["fall_rate_ci95"][0] for j in order], dtype=float)
        hi = np.array([rows[cfg.levels[j]]["fall_rate_ci95"][1] for j in order], dtype=float)
        ax1.fill_between(x, lo, hi, color=c, alpha=0.15, lw=0)
        ax1.plot(x, get("fall_rate"), marker=m, color=c, ms=5, lw=1.8, label=p.label)
        mu, sd = get("speed_cm_s_mean"), get("speed_cm_s_std")
        ax2.fill_between(x, mu - np.nan_to_num(sd), mu + np.nan_to_num(sd), color=c, alpha=0.15, lw=0)
        ax2.plot(x, mu, marker=m, color=c, ms=5, lw=1.8, label=p.label)
        for xi, yi, ni, ti in zip(x, mu, get("speed_n"), get("trials")):
            if np.isfinite(yi) and ni < ti:  # fewer walkers than trials: say how many the mean is over
                ax2.annotate(f"{int(ni)}", (xi, yi), textcoords="offset points", xytext=(4, 4), fontsize=7,
                             color=c)
    ax1.set_ylim(-0.03, 1.03)
    ax1.set_ylabel("fall rate (band: 95 % Wilson)")
    ax1.grid(alpha=0.3)
    ax1.legend(loc="upper left", fontsize=9, title="policy", title_fontsize=9)
    ax2.set_ylabel("speed of non-fallers [cm/s]\n(band: ± 1 std)")
    ax2.set_xlabel(cfg.level_name)
    ax2.grid(alpha=0.3)
    ax2.set_ylim(bottom=min(0.0, ax2.get_ylim()[0]))
    if title is None:
        where = (f"{cfg.terrain} terrain" if cfg.axis == "terrain"
                 else f"{cfg.axis} sweep on " + (f"{cfg.terrain} a={cfg.amplitude:g}" if cfg.terrain
                                                 else "the profile's terrain"))
        prof = f", profile {cfg.profile['name']}" if cfg.profile else ""
        title = f"Stress test: {cfg.world} world{prof}, {where}, {cfg.trials} trials per point, seed {cfg.seed}"
    fig.suptitle(title, fontsize=10)
    ax2.text(0.99, 0.02, "small numbers: trials that did not fall (when not all); gaps: every trial fell",
             transform=ax2.transAxes, ha="right", va="bottom", fontsize=7, color="0.4")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=130)
    _atomic_write_bytes(path, buf.getvalue())


def format_table(table: Sequence[dict], cfg: StressConfig) -> str:
    """The table as text, one block per policy."""
    lines = []
    name = cfg.level_name
    for p in cfg.policies:
        lines.append(f"policy {p.label} ({p.source}, θ hash {p.theta_hash})")
        lines.append(f"  {name:>24}  {'falls':>7}  {'fall rate [95% CI]':>20}  {'speed [cm/s] non-fallers':>26}"
                     f"  {'dist. before fall [cm]':>22}")
        for r in (r for r in table if r["policy"] == p.label):
            lo, hi = r["fall_rate_ci95"]
            fr = f"{r['fall_rate']:.2f} [{lo:.2f}, {hi:.2f}]" if r["trials"] else "-"
            sp = (f"{r['speed_cm_s_mean']:.2f} ± {r['speed_cm_s_std']:.2f} (n={r['speed_n']})" if r["speed_n"] > 1
                  else f"{r['speed_cm_s_mean']:.2f} (n=1)" if r["speed_n"] == 1 else "- (all fell)")
            d = r["distance_before_fall_m_mean"]
            ds = f"{100 * d:.1f}" if not math.isnan(d) else "-"
            lines.append(f"  {cfg.level_display(r['level']):>24.4g}  {r['falls']:>3}/{r['trials']:<3}  {fr:>20}"
                         f"  {sp:>26}  {ds:>22}")
    return "\n".join(lines)


# --------------------------------------------------------------------------------------------
# The run
# --------------------------------------------------------------------------------------------


def default_out(cfg: StressConfig) -> Path:
    """``runs/stress-<world>-<terrain or effect>-seed<seed>``."""
    what = cfg.terrain if cfg.axis == "terrain" else cfg.axis
    return Path("runs") / f"stress-{cfg.world}-{what}-seed{cfg.seed}"


def _ordered(rows: dict[tuple, dict], cfg: StressConfig) -> list[dict]:
    """Rows by policy, level, trial (the configuration's order); rows of other policies or levels
    (kept from an earlier, larger run in the same directory) after them."""
    pi = {(p.label, p.theta_hash): i for i, p in enumerate(cfg.policies)}
    li = {v: i for i, v in enumerate(cfg.levels)}
    big = len(pi) + len(li) + 1
    return sorted(rows.values(), key=lambda r: (pi.get((r["policy"], r["theta_hash"]), big), r["policy"],
                                                li.get(r["level"], big), r["level"], r["trial"]))


def _check_resume(out: Path, cfg: StressConfig) -> list[dict]:
    """Rows already in ``out`` that belong to this configuration (after checking its settings)."""
    cfg_path, trials_path = out / "stress.json", out / "trials.csv"
    if cfg_path.exists():
        try:
            old = json.loads(cfg_path.read_text())
        except (OSError, json.JSONDecodeError) as exc:
            raise ValueError(f"{cfg_path}: cannot read the settings of the run there ({exc})") from None
        new = json.loads(json.dumps(cfg.invariants()))
        diff = [k for k in (*_INVARIANTS, "robot") if old.get(k, "nao" if k == "robot" else None)
                != new.get(k, "nao" if k == "robot" else None)]
        if diff:
            raise ValueError(f"{out} holds a stress run with other settings ({', '.join(diff)}); "
                             "give another --out or remove it")
    if not trials_path.exists():
        return []
    return read_trials(trials_path)


def run_stress(cfg: StressConfig, out: str | os.PathLike | None = None, *, executor=None,
               workers: int | None = None, ray_address: str | None = None, rerun: bool = False,
               reporter: Reporter | None = None, chunk: int | None = None) -> dict:
    """Run (or resume) a stress test and write its files (module docstring).

    Args:
        cfg: from :func:`make_config`.
        out: run directory (default :func:`default_out`); trials already there are reused.
        executor: an executor (``.map``); default ``make_executor(workers, ray_address)``, closed
            at the end.
        rerun: write ``rerun/<policy>.rrd`` with the worst trial of each level.
        reporter: progress (default: quiet).
        chunk: episodes between two saves of ``trials.csv`` (default 150).

    Returns:
        dict: ``rows`` (the table, :data:`SUMMARY_COLUMNS`), ``out``, ``files``, ``episodes``
        (planned), ``ran`` (run now), ``resumed`` (found done), ``wall_s``, ``executor``,
        ``workers``, ``config``, ``worst`` (with ``rerun``), ``table`` (text).

    Raises:
        ValueError: ``out`` holds a run with other settings or a malformed ``trials.csv``;
        experiments.runtime.executors.TaskFailed: an episode failed twice.
    """
    from experiments.runtime.batch import map_episodes  # lazy: loads the engines and torch

    report = reporter or Reporter.quiet()
    out = Path(out) if out is not None else default_out(cfg)
    old_rows = _check_resume(out, cfg)
    out.mkdir(parents=True, exist_ok=True)
    clock = WallClock(out)  # the run's time over all the invocations that resumed it
    _atomic_write_bytes(out / "stress.json", json.dumps(cfg.to_dict(), indent=1).encode())
    trials = plan_tasks(cfg)
    rows: dict[tuple, dict] = {_key(r): r for r in old_rows}
    todo = [t for t in trials if t.key not in rows]
    resumed = len(trials) - len(todo)
    if resumed:
        report.say(f"{resumed} of {len(trials)} episodes already in {out / 'trials.csv'}; running the other {len(todo)}")
    own = executor is None
    ex = make_executor(workers, ray_address) if own else executor
    trials_csv = out / "trials.csv"
    try:
        n = chunk or 150  # trials.csv is rewritten after each chunk (resume point)
        try:
            with report.count(len(trials), "stress", initial=resumed) as update:
                for i in range(0, len(todo), n):
                    part = todo[i:i + n]
                    for t, r in zip(part, map_episodes(ex, [t.task for t in part], progress=update)):
                        rows[t.key] = trial_row(t, r)
                    write_csv(_ordered(rows, cfg), TRIAL_COLUMNS, trials_csv)
        except KeyboardInterrupt:
            report.say(f"stopped; {len(rows)} episodes are saved in {trials_csv}: run the same command again to resume")
            raise
        all_rows = _ordered(rows, cfg)
        write_csv(all_rows, TRIAL_COLUMNS, trials_csv)
        table = summarize(all_rows, cfg)
        files = {"config": str(out / "stress.json"), "trials_csv": str(trials_csv),
                 "trials_parquet": str(out / "trials.parquet"), "summary_csv": str(out / "summary.csv"),
                 "png": str(out / "stress.png")}
        write_parquet(all_rows, out / "trials.parquet")
        write_csv([{**r, "fall_rate_ci95_low": r["fall_rate_ci95"][0], "fall_rate_ci95_high": r["fall_rate_ci95"][1]}
                   for r in table], SUMMARY_CSV_COLUMNS, out / "summary.csv")
        plot_stress(table, cfg, out / "stress.png")
        result: dict[str, Any] = {}
        if rerun:
            result["worst"] = _rerun_worst(cfg, all_rows, ex, out, files)
    finally:
        if own:
            ex.close()
    result.update({"rows": table, "out": str(out), "files": files, "episodes": len(trials), "ran": len(todo),
                   "resumed": resumed, "wall_s": clock.save(), "executor": getattr(ex, "name", "?"),
                   "workers": int(getattr(ex, "workers", 1)), "config": cfg.to_dict(),
                   "table": format_table(table, cfg)})
    return result


def _rerun_worst(cfg: StressConfig, rows: list[dict], ex, out: Path, files: dict) -> list[dict]:
    """Re-run the worst trial of each policy and level with recording on, check that it repeats,
    and log them into ``rerun/<policy>.rrd`` (one entity per level)."""
    from envs import Recording  # lazy: loads the engines
    from experiments.runtime.tasks import run_episode  # lazy: loads the engines
    from experiments.runtime.worlds import terrain_field
    from experiments.viz import log_rollouts_to_rrd  # lazy: loads the engines

    worst = worst_trials(rows, cfg)
    by_key = {t.key: t for t in plan_tasks(cfg)}
    pol = {p.label: p for p in cfg.policies}
    trials = [by_key[(label, pol[label].theta_hash, level, r["trial"])] for (label, level), r in worst.items()]
    results = ex.map(run_episode, [t.task.replace(record=True) for t in trials])
    notes = []
    recs: dict[str, dict[str, Recording]] = {}
    terrains: dict[str, dict] = {}
    for t, res in zip(trials, results):
        old = worst[(t.policy, t.level)]
        same = (res.fell == old["fell"] and abs(res.speed_cm_s - old["speed_cm_s"]) < 1e-6)
        lab = f"L{cfg.levels.index(t.level):02d}_{cfg.level_display(t.level):g}_trial{t.trial}".replace("-", "m")
        recs.setdefault(t.policy, {})[lab] = Recording(*res.recording)
        terrains.setdefault(t.policy, {})[lab] = terrain_field(*t.task.terrain) if t.task.terrain else None
        notes.append({"policy": t.policy, "level": t.level, "trial": t.trial, "fell": res.fell,
                      "fall_time_s": res.fall_time_s, "speed_cm_s": res.speed_cm_s, "label": lab,
                      "repeats": bool(same)})
    paths = {}
    for label, rs in recs.items():
        path = out / "rerun" / f"{label}.rrd"
        path.parent.mkdir(parents=True, exist_ok=True)
        # terrains: only the known ones (None in a sweep on the profile's terrain: viz regenerates it)
        known = {k: v for k, v in terrains[label].items() if v is not None}
        log_rollouts_to_rrd(rs, path, terrains=known or None)
        paths[label] = str(path)
    for n in notes:
        n["rrd"] = paths[n["policy"]]
    files["rrd"] = sorted(paths.values())
    return notes
