"""What the learned worlds of a fidelity run are built from, per draw of real data.

For every draw d of the real data (``data_seeds`` draws, each from seeds of its own):

* the real world's **identification** (the identified and hybrid worlds): excitation logs in the air
  and stepping on the walking ground, two diagnoses (:func:`experiments.runtime.identify.identify_real`),
  after the engine-gap calibration that ships with the package;
* the **grounding walks** (the grounded worlds): ``real`` walks of θ0 in the real world and ``sim``
  walks with exploration noise in the sim the world grounds (the plain sim, or the identified one);
* the **fits**: one action transformer per grounded world and draw, exactly as ``sgatwalk optimize``'s
  first grounding step fits it (:class:`experiments.runtime.tasks.FitTask`).

Each draw is an independent job (:func:`prepare_draw_job`; side by side on a Ray cluster, one after the
other on this machine, its walks and fits on the executor's workers either way). Everything is cached
in the run directory (``identified/d<draw>/``, ``data/``, ``models/``) and reused on a resume.
"""

from __future__ import annotations

import contextlib
import json
import os
import time

from common.files import atomic_write_text
from experiments.fidelity.config import FIT, GROUND_REAL, GROUND_SIM, IDENT, PHASES, FidelityConfig
from experiments.fidelity.scoring import recording_summary
from experiments.runtime.grounding import IDENTIFY_ROUNDS, identified_delay
from experiments.runtime.identify import (ENGINE_GAP_SEED, calibrate_engines, excitation_tasks, identify_real,
                                          record_excitation_task)
from experiments.runtime.progress import Reporter
from experiments.runtime.seeds import derive_seed, derive_seeds
from experiments.runtime.tasks import EpisodeTask, FitTask, fit_grounding_task
from experiments.runtime.worlds import WorldSpec


class Phases:
    """Wall time per phase of :data:`experiments.fidelity.config.PHASES`, accumulated over a run's
    invocations in ``phases.json`` (``run_dir`` None: in memory only, as a job keeps them for its run)."""

    def __init__(self, run_dir: str | None):
        self.path = os.path.join(run_dir, "phases.json") if run_dir else None
        self.seconds: dict[str, float] = {}
        if self.path:
            try:
                with open(self.path) as f:
                    self.seconds = {k: float(v) for k, v in json.load(f).items() if k in PHASES}
            except (OSError, ValueError, AttributeError):  # none yet, or unreadable: count from here
                self.seconds = {}

    @contextlib.contextmanager
    def __call__(self, name: str):
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.add({name: time.perf_counter() - t0})

    def add(self, seconds: dict[str, float]) -> None:
        """Add seconds per phase (a job's) and save."""
        for k, v in seconds.items():
            self.seconds[k] = self.seconds.get(k, 0.0) + float(v)
        if self.path:
            atomic_write_text(self.path, json.dumps(self.seconds))

    def ordered(self) -> dict[str, float]:
        """Seconds per phase so far, every invocation included, in run order."""
        return {k: self.seconds[k] for k in PHASES if k in self.seconds}


class WorldData:
    """The identification, grounding walks and fitted transformers of one draw of a fidelity run's
    learned worlds.

    Args:
        cfg: the run's settings; specs: its worlds; run_dir: its directory; draw: the draw of real
        data; executor: where walks and fits run; reporter: progress; phases: the phase clock.
    """

    def __init__(self, cfg: FidelityConfig, specs: list[WorldSpec], run_dir: str, draw: int, executor,
                 reporter: Reporter, phases: Phases):
        self.cfg, self.specs, self.run_dir, self.draw = cfg, specs, run_dir, draw
        self.ex, self.report, self.phase = executor, reporter, phases
        self._queued: dict[str, EpisodeTask] = {}

    # ---------------------------------------------------------------- walks
    def walks(self, world: str, seeds: list[int], tag: str, theta, **kw) -> list[str]:
        """The paths of the recordings of ``theta`` in ``world`` on ``seeds`` under ``data/`` (cached);
        those not recorded yet are queued for :meth:`record_walks`."""
        paths = [os.path.join(self.run_dir, "data", f"{tag}_{s}.parquet") for s in seeds]
        for s, p in zip(seeds, paths):
            if not os.path.exists(p):
                self._queued.setdefault(p, EpisodeTask(
                    world, tuple(theta), s, self.cfg.seconds, robot=self.cfg.robot, profile=self.cfg.profile,
                    stochasticity=self.cfg.stochasticity if world == "real" else 0.0, record=True, **kw))
        return paths

    def record_walks(self) -> None:
        """Record every queued walk in one map on the executor (each carries its own seed)."""
        from envs import Recording  # lazy: loads the engines
        from experiments.runtime.batch import map_episodes  # lazy: loads the engines

        todo, self._queued = list(self._queued.items()), {}
        if not todo:
            return
        t0 = time.perf_counter()
        self.report.say(f"recording {len(todo)} grounding walks")
        with self.phase("grounding walks"), self.report.count(len(todo), "grounding walks") as update:
            for (p, _), r in zip(todo, map_episodes(self.ex, [t for _, t in todo], progress=update)):
                Recording(*r.recording).to_parquet(p)
        self.report.say(f"  recorded ({time.perf_counter() - t0:.0f} s)")

    # ---------------------------------------------------------------- identification
    def _identify_args(self) -> dict:
        """Where and from what seed this draw's identification records (what :func:`identify_real` and
        :func:`excitation_tasks` share)."""
        cfg = self.cfg
        return {"out_dir": os.path.join(self.run_dir, "identified", f"d{self.draw}"),
                "seed": derive_seed(cfg.seed, IDENT, self.draw) % 1_000_000, "profile": cfg.profile,
                "n_fixed": cfg.identify_fixed_logs, "n_floating": cfg.identify_floating_logs,
                "seconds": cfg.identify_seconds, "stochasticity": cfg.stochasticity}

    def identify(self, calibration: dict) -> dict:
        """This draw's identification of the real world: its excitation logs recorded side by side, then
        the diagnoses (:func:`experiments.runtime.identify.identify_real`).

        Args:
            calibration: :func:`experiments.runtime.identify.calibrate_engines`'s output.
        """
        todo = excitation_tasks(**self._identify_args())
        if todo:
            t0 = time.perf_counter()
            self.report.say(f"recording {len(todo)} sets of excitation logs ({sum(t['n_logs'] for t in todo)} logs)")
            with self.phase("excitation logs"):
                list(self.ex.map(record_excitation_task, todo))
            self.report.say(f"  recorded ({time.perf_counter() - t0:.0f} s)")
        with self.phase("diagnoses"):
            r = identify_real(**self._identify_args(), calibration=calibration,
                              time_budget_s=self.cfg.identify_budget_s, rounds=IDENTIFY_ROUNDS)
        self.report.say(f"identified: {len(r['effects'])} terms, ground Sq {1000 * r['terrain_rms_height']:.2f} "
                        f"mm, {r['logs']} logs ({r['wall_s']:.0f} s)"
                        + "".join(f"; WARNING: the {k} diagnosis ran out of time (raise --identify-budget)"
                                  for k in r.get("time_budget_reached", [])))
        return r

    # ---------------------------------------------------------------- fits
    def model_dir(self, spec: WorldSpec) -> str:
        return os.path.join(self.run_dir, "models", f"{spec.key}_d{self.draw}")

    def prepare(self, theta0, calibration: dict | None) -> dict:
        """This draw's identification, grounding walks and fitted transformers for every world.

        Args:
            theta0: the gait the grounding walks walk (SI).
            calibration: the engine-gap calibration (:func:`calibrate_engines`; None when no world
                needs an identification).

        Returns:
            ``{world name: {"transformer": dir or None, "identified": [reports] or None, "real_walks",
            "real_seconds", "real_walk_falls", "excitation_logs", "excitation_seconds", "effects",
            "terrain_rms_height", "delay", "real_paths"}}``.
        """
        idn = self.identify(calibration) if any(s.needs_identification for s in self.specs) else None
        out: dict = {}
        fits = []
        for s in self.specs:
            info: dict = {"transformer": None, "identified": None, "real_walks": 0, "real_seconds": 0.0,
                          "excitation_logs": 0, "excitation_seconds": 0.0}
            if s.needs_identification:
                info.update(identified=list(idn["reports"]), excitation_logs=idn["logs"],
                            excitation_seconds=idn["seconds"], effects=idn["effects"],
                            terrain_rms_height=idn["terrain_rms_height"])
            if s.grounded:
                fits.append(self._grounding(s, info, theta0))
            out[s.name] = info
        self.record_walks()
        for info in (i for i in out.values() if i.get("real_paths")):
            walks = [recording_summary(p) for p in info["real_paths"]]
            info["real_walks"] = len(walks)
            info["real_seconds"] = float(sum(w[0] for w in walks))
            info["real_walk_falls"] = int(sum(w[1] for w in walks))
        self._fit([f for f in fits if not os.path.exists(os.path.join(f.out, "transformer.json"))], len(fits))
        return out

    def _grounding(self, s: WorldSpec, info: dict, theta0) -> FitTask:
        """Queue this draw's grounding walks of world ``s`` and return its fit (``info`` gains the
        transformer's directory, the real walks and the delay)."""
        cfg, d = self.cfg, self.draw
        hybrid = s.needs_identification
        real = self.walks("real", derive_seeds(cfg.seed, GROUND_REAL, d, n=int(s.get("real"))), f"real_d{d}", theta0)
        noise = float(s.get("explore"))
        sim = self.walks("identified" if hybrid else "sim", derive_seeds(cfg.seed, GROUND_SIM, d, n=int(s.get("sim"))),
                         f"{'ident' if hybrid else 'sim'}_d{d}_n{noise:g}", theta0,
                         action_noise=noise, identified=tuple(info["identified"] or ()))
        delay = identified_delay(info["identified"]) if s.get("delay") == "auto" else None
        gcfg = s.grounding_config(delay=delay)
        info.update(transformer=self.model_dir(s), real_paths=real, data_gait=list(theta0), delay=int(gcfg.delay))
        return FitTask(tuple(real), tuple(sim), gcfg.to_dict(), int(s.get("history")),
                       derive_seed(cfg.seed, FIT, d) % 1_000_000, self.model_dir(s), cfg.robot, f"{s.name} draw {d}")

    def _fit(self, todo: list[FitTask], total: int) -> None:
        if not todo:
            return
        t0 = time.perf_counter()
        self.report.say(f"fitting {len(todo)} transformers ({total - len(todo)} resumed)")
        with self.phase("fits"):
            fitted = self.ex.map(fit_grounding_task, todo)
        for f, r in zip(todo, fitted):
            self.report.say(f"  {f.label}: forward val {r.forward_val:.3f}, inverse val {r.inverse_val:.3f} "
                            f"({r.n_real} real / {r.n_sim} sim transitions, {r.wall_s:.0f} s)")
        self.report.say(f"fits done ({time.perf_counter() - t0:.0f} s)")


def prepare_draw_job(job, executor) -> tuple[dict, dict]:
    """One draw of a fidelity run's real data, as an executor job (:meth:`SerialExecutor.jobs
    <experiments.runtime.executors.SerialExecutor.jobs>`): its identification, grounding walks and fits,
    cached in the run directory.

    Args:
        job: ``(cfg, run_dir, draw, theta0, calibration, verbose)``; executor: where its walks and fits
            run; ``verbose`` False: no messages.

    Returns:
        ``(WorldData.prepare's result, seconds per phase)``.
    """
    cfg, run_dir, draw, theta0, calibration, verbose = job
    phases = Phases(None)
    reporter = Reporter(f"fidelity draw {draw}") if verbose else Reporter.quiet()
    data = WorldData(cfg, cfg.validate(), run_dir, draw, executor, reporter, phases)
    return data.prepare(theta0, calibration), phases.seconds


def prepare_draws(cfg: FidelityConfig, specs: list[WorldSpec], run_dir: str, executor, reporter: Reporter,
                  phases: Phases, theta0) -> dict:
    """Every draw's identification, grounding walks and fits (:func:`prepare_draw_job`), the draws as
    independent jobs after the engine-gap calibration they share.

    Returns:
        ``{world name: {draw: info}}`` (see :meth:`WorldData.prepare`).
    """
    calibration = None
    if any(s.needs_identification for s in specs):
        t0 = time.perf_counter()
        # one constant of the testbed, whatever the run's seed; the package ships it for the pinned engines
        calibration = calibrate_engines(os.path.join(run_dir, "identified", "calibration"), seed=ENGINE_GAP_SEED,
                                        floating=cfg.identify_floating_logs > 0)
        reporter.say(f"engine-gap calibration ready ({time.perf_counter() - t0:.0f} s)")
    draws = list(range(cfg.data_seeds))
    done = executor.jobs(prepare_draw_job, [(cfg, run_dir, d, list(theta0), calibration, reporter.stream is not None) for d in draws],
                         [f"draw {d}" for d in draws], reporter)
    out: dict = {s.name: {} for s in specs}
    for d, (per_world, seconds) in zip(draws, done):
        phases.add(seconds)
        for name, info in per_world.items():
            out[name][d] = info
    return out


__all__ = ["Phases", "WorldData", "prepare_draw_job", "prepare_draws"]
