"""What the learned worlds of a fidelity run are built from, per draw of real data.

For every draw d of the real data (``data_seeds`` draws, each from seeds of its own):

* the real world's **identification** (the identified and hybrid worlds): excitation logs in the air
  and stepping on the walking ground, two diagnoses (:func:`experiments.runtime.identify.identify_real`),
  after the engine-gap calibration that ships with the package;
* the **grounding walks** (the grounded worlds): ``real`` walks of θ0 in the real world and ``sim``
  walks with exploration noise in the sim the world grounds (the plain sim, or the identified one);
* the **fits**: one action transformer per grounded world and draw, exactly as ``sgatwalk optimize``'s
  first grounding step fits it (:class:`experiments.runtime.tasks.FitTask`).

Everything is cached in the run directory (``identified/d<draw>/``, ``data/``, ``models/``) and reused
on a resume; walks and fits of all worlds and draws go to the executor together.
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
    invocations in ``phases.json``."""

    def __init__(self, run_dir: str):
        self.path = os.path.join(run_dir, "phases.json")
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
            self.seconds[name] = self.seconds.get(name, 0.0) + time.perf_counter() - t0
            atomic_write_text(self.path, json.dumps(self.seconds))

    def ordered(self) -> dict[str, float]:
        """Seconds per phase so far, every invocation included, in run order."""
        return {k: self.seconds[k] for k in PHASES if k in self.seconds}


class WorldData:
    """The identifications, grounding walks and fitted transformers of a fidelity run's learned worlds.

    Args:
        cfg: the run's settings; specs: its worlds; run_dir: its directory; executor: where walks and
        fits run; reporter: its progress; phases: its phase clock.
    """

    def __init__(self, cfg: FidelityConfig, specs: list[WorldSpec], run_dir: str, executor, reporter: Reporter,
                 phases: Phases):
        self.cfg, self.specs, self.run_dir, self.ex, self.report, self.phase = cfg, specs, run_dir, executor, reporter, phases
        self._queued: dict[str, EpisodeTask] = {}

    # ---------------------------------------------------------------- walks
    def walks(self, world: str, seeds: list[int], tag: str, theta, **kw) -> list[str]:
        """The paths of the recordings of ``theta`` in ``world`` on ``seeds`` under ``data/`` (cached);
        those not recorded yet are queued for :meth:`record_walks`."""
        paths = [os.path.join(self.run_dir, "data", f"{tag}_{s}.parquet") for s in seeds]
        for s, p in zip(seeds, paths):
            if not os.path.exists(p):
                self._queued.setdefault(p, EpisodeTask(world, tuple(theta), s, self.cfg.seconds, robot=self.cfg.robot,
                                                       profile=self.cfg.profile, record=True, **kw))
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
    def _identify_args(self, draw: int) -> dict:
        """Where and from what draw ``draw``'s identification records (what :func:`identify_real` and
        :func:`excitation_tasks` share)."""
        cfg = self.cfg
        return {"out_dir": os.path.join(self.run_dir, "identified", f"d{draw}"),
                "seed": derive_seed(cfg.seed, IDENT, draw) % 1_000_000, "profile": cfg.profile,
                "n_fixed": cfg.identify_fixed_logs, "n_floating": cfg.identify_floating_logs,
                "seconds": cfg.identify_seconds}

    def identify(self) -> dict[int, dict]:
        """Every draw's identification of the real world (none when no world needs one): the excitation
        logs of all draws recorded side by side first, then the diagnoses one by one (each keeps the
        cores busy itself).

        Returns:
            ``{draw: identify_real's result}``.
        """
        if not any(s.needs_identification for s in self.specs):
            return {}
        cfg = self.cfg
        t0 = time.perf_counter()
        # one constant of the testbed, whatever the run's seed; the package ships it for the pinned engines
        calibration = calibrate_engines(os.path.join(self.run_dir, "identified", "calibration"), seed=ENGINE_GAP_SEED,
                                        floating=cfg.identify_floating_logs > 0)
        self.report.say(f"engine-gap calibration ready ({time.perf_counter() - t0:.0f} s)")
        todo = [t for d in range(cfg.data_seeds) for t in excitation_tasks(**self._identify_args(d))]
        if todo:
            t0 = time.perf_counter()
            self.report.say(f"recording {len(todo)} sets of excitation logs ({sum(t['n_logs'] for t in todo)} logs)")
            with self.phase("excitation logs"):
                list(self.ex.map(record_excitation_task, todo))
            self.report.say(f"  recorded ({time.perf_counter() - t0:.0f} s)")
        out = {}
        for d in range(cfg.data_seeds):
            with self.phase("diagnoses"):
                out[d] = r = identify_real(**self._identify_args(d), calibration=calibration,
                                           time_budget_s=cfg.identify_budget_s, rounds=IDENTIFY_ROUNDS)
            self.report.say(f"identified draw {d}: {len(r['effects'])} terms, ground Sq {1000 * r['terrain_rms_height']:.2f} "
                            f"mm, {r['logs']} logs ({r['wall_s']:.0f} s)"
                            + "".join(f"; WARNING: the {k} diagnosis ran out of time (raise --identify-budget)"
                                      for k in r.get("time_budget_reached", [])))
        return out

    # ---------------------------------------------------------------- fits
    def model_dir(self, spec: WorldSpec, draw: int) -> str:
        return os.path.join(self.run_dir, "models", f"{spec.key}_d{draw}")

    def prepare(self, theta0) -> dict:
        """Identifications, grounding walks and fitted transformers for every world and draw.

        Args:
            theta0: the gait the grounding walks walk (SI).

        Returns:
            ``{world name: {draw: {"transformer": dir or None, "identified": [reports] or None,
            "real_walks", "real_seconds", "real_walk_falls", "excitation_logs", "excitation_seconds",
            "effects", "terrain_rms_height", "delay", "real_paths"}}}``.
        """
        cfg = self.cfg
        idents = self.identify()
        out: dict = {s.name: {} for s in self.specs}
        fits = []
        for d in range(cfg.data_seeds):
            for s in self.specs:
                info: dict = {"transformer": None, "identified": None, "real_walks": 0, "real_seconds": 0.0,
                              "excitation_logs": 0, "excitation_seconds": 0.0}
                if s.needs_identification:
                    idn = idents[d]
                    info.update(identified=list(idn["reports"]), excitation_logs=idn["logs"],
                                excitation_seconds=idn["seconds"], effects=idn["effects"],
                                terrain_rms_height=idn["terrain_rms_height"])
                if s.grounded:
                    fits.append(self._grounding(s, d, info, theta0))
                out[s.name][d] = info
        self.record_walks()
        for info in (i for per in out.values() for i in per.values() if i.get("real_paths")):
            walks = [recording_summary(p) for p in info["real_paths"]]
            info["real_walks"] = len(walks)
            info["real_seconds"] = float(sum(w[0] for w in walks))
            info["real_walk_falls"] = int(sum(w[1] for w in walks))
        self._fit([f for f in fits if not os.path.exists(os.path.join(f.out, "transformer.json"))], len(fits))
        return out

    def _grounding(self, s: WorldSpec, d: int, info: dict, theta0) -> FitTask:
        """Queue draw ``d``'s grounding walks of world ``s`` and return its fit (``info`` gains the
        transformer's directory, the real walks and the delay)."""
        cfg = self.cfg
        hybrid = s.needs_identification
        real = self.walks("real", derive_seeds(cfg.seed, GROUND_REAL, d, n=int(s.get("real"))), f"real_d{d}", theta0)
        noise = float(s.get("explore"))
        sim = self.walks("identified" if hybrid else "sim", derive_seeds(cfg.seed, GROUND_SIM, d, n=int(s.get("sim"))),
                         f"{'ident' if hybrid else 'sim'}_d{d}_n{noise:g}", theta0,
                         action_noise=noise, identified=tuple(info["identified"] or ()))
        delay = identified_delay(info["identified"]) if s.get("delay") == "auto" else None
        gcfg = s.grounding_config(delay=delay)
        info.update(transformer=self.model_dir(s, d), real_paths=real, data_gait=list(theta0), delay=int(gcfg.delay))
        return FitTask(tuple(real), tuple(sim), gcfg.to_dict(), int(s.get("history")),
                       derive_seed(cfg.seed, FIT, d) % 1_000_000, self.model_dir(s, d), cfg.robot, f"{s.name} draw {d}")

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


__all__ = ["Phases", "WorldData"]
