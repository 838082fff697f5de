"""How well does each training world predict the real world? (``sgatwalk fidelity``)

A grounded sim is only worth what it predicts about the real world. For a **panel of gaits** (θ0,
``gaits`` gaits drawn uniformly in the optimizer's trust region of ±``box`` around θ0 in the
normalized space CMA-ES searches, and any θ files given), this measures:

* the **real fitness** of every gait over ``real_trials`` paired real trials (trial j of every gait
  runs on the same seed: the same terrain, effects and noise);
* each **training world's** fitness for the same gaits (the mean over ``episodes`` episodes on seeds
  shared by the gaits; one for a deterministic world: the sim and GAT). Worlds that learn from real
  data are fitted ``data_seeds`` times, each on an independent draw of that data, exactly as
  ``sgatwalk optimize``'s first grounding step fits them (:mod:`experiments.fidelity.prepare`); the
  real world itself (``real``) walks fresh seeds per draw.

The scores (:mod:`experiments.fidelity.scoring`): per world and draw Spearman ρ with the real fitness,
MAE, bias, Brier score of the fall frequencies and the regret of its pick, with their spread over the
draws; paired bootstrap tests between worlds; the ceiling of ρ that the real trials' own noise
allows. Each grounded world is also teacher-forced along its own grounding walks
(``sgat.TeacherForcedEnv``): what the inverse models and action grounding can reproduce, apart from
what the forward model misses. Everything random is keyed by (seed, purpose, ...) through
``numpy.random.SeedSequence``; a run directory resumes where it stopped, and a run resumed with more
worlds or episodes per gait walks only what it lacks.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os

import numpy as np

from common.files import WallClock, atomic_write_text, jsonable
from experiments.fidelity.config import PANEL, REAL, REAL_WORLD, WORLD, FidelityConfig, param_gait_names
from experiments.fidelity.prepare import Phases, prepare_draws
from experiments.fidelity.report import format_table, plot, plot_episodes
from experiments.fidelity.scoring import (draw_metrics, episode_counts, episodes_rows, group_rows, paired_rows,
                                          replay_summary, summary)
from experiments.runtime.progress import Reporter
from experiments.runtime.rundir import EpisodeLog
from experiments.runtime.seeds import derive_seeds
from experiments.runtime.stats import bootstrap_spearman, brier_score, split_half_reliability
from experiments.runtime.tasks import EpisodeTask, ReplayTask, episode_task, replay_walk_task
from experiments.runtime.worlds import WorldSpec


def drawn_panel(params_class, seed: int, gaits: int, box: float) -> list[dict]:
    """The drawn part of a fidelity panel: θ0 and ``gaits`` gaits drawn uniformly in ±``box`` around it
    in the normalized space CMA-ES searches (clipped to [0, 1]), from the run seed's panel stream:
    ``[{"name": "theta0" | "boxNN", "theta": [16 SI values]}]`` (what ``sgatwalk fidelity --seed``
    walks; ``params_class`` a :func:`walk_engine.params_for` class)."""
    th0 = params_class.initial()
    u0 = th0.to_vector()
    rng = np.random.default_rng(np.random.SeedSequence([seed, PANEL]))
    out = [{"name": "theta0", "theta": th0.to_array().tolist()}]
    for i in range(gaits):
        u = np.clip(u0 + rng.uniform(-box, box, len(u0)), 0.0, 1.0)
        out.append({"name": f"box{i:02d}", "theta": params_class.from_vector(u).to_array().tolist()})
    return out


def inverse_signature(model_dir: str) -> str:
    """A hash of a saved transformer's inverse models (their weights) and α: what teacher forcing uses of it."""
    from sgat.models import InverseModel  # lazy: sgat loads torch

    h = hashlib.sha1()
    with open(os.path.join(model_dir, "transformer.json")) as f:
        h.update(str(json.load(f)["alpha"]).encode())
    for name in sorted(os.listdir(model_dir)):
        if name.startswith("inverse"):
            for k, v in sorted(InverseModel.load(os.path.join(model_dir, name)).state_dict().items()):
                h.update(k.encode() + v.detach().cpu().numpy().tobytes())
    return h.hexdigest()


class Fidelity:
    """Runs (or resumes) a fidelity measurement in ``run_dir`` with ``executor``.

    Files: ``config.json``, ``panel.json`` (the gaits), ``episodes.jsonl`` (one line per finished
    episode, appended as batches finish), ``data/`` (grounding walks), ``models/`` (transformers per
    world and draw), ``identified/`` (excitation logs and diagnoses), ``fidelity.json`` (the result),
    ``fidelity.png``, ``fidelity_episodes.png`` (fidelity against episodes per gait, where a
    stochastic world has more than one), ``table.txt``, ``timing.json`` (wall time of every
    invocation so far) and ``phases.json`` (its split over the run's phases).
    """

    def __init__(self, cfg: FidelityConfig, run_dir: str, executor, *, reporter: Reporter | None = None):
        # absolute: the tasks and draw jobs name its files, and a Ray worker may run elsewhere
        self.cfg, self.run_dir, self.ex = cfg, os.path.abspath(run_dir), executor
        self.specs = cfg.validate()
        self.report = reporter or Reporter.quiet()
        os.makedirs(run_dir, exist_ok=True)
        self.phase = Phases(run_dir)

    def phases(self) -> dict[str, float]:
        """Seconds spent in each phase so far, every invocation included, in run order."""
        return self.phase.ordered()

    # ---------------------------------------------------------------- panel
    def panel(self) -> list[dict]:
        """θ0, the drawn gaits and the given θ files: ``[{"name", "theta"}]`` (saved to panel.json)."""
        path = os.path.join(self.run_dir, "panel.json")
        if os.path.exists(path):
            with open(path) as f:
                return json.load(f)["gaits"]
        cfg = self.cfg
        P = cfg.params_class
        gaits = drawn_panel(P, cfg.seed, cfg.gaits, cfg.box)
        for name, p in zip(param_gait_names(cfg.params), cfg.params):
            gaits.append({"name": name, "theta": P.load(p).to_array().tolist()})
        atomic_write_text(path, json.dumps({"gaits": gaits}, indent=1))
        return gaits

    def data_gait(self) -> list[float]:
        """θ0: the gait every grounding walk walks (in SI units)."""
        return self.cfg.params_class.initial().to_array().tolist()

    # ---------------------------------------------------------------- episodes
    def world_tasks(self, spec: WorldSpec, draw: int, info: dict, gaits: list[dict]) -> list[EpisodeTask]:
        """The episodes of ``spec`` (draw ``draw``) on every gait: the same episode seeds for every
        world, draw and gait; the real world itself on fresh seeds per draw."""
        cfg = self.cfg
        n = 1 if spec.deterministic else cfg.episodes
        seeds = derive_seeds(cfg.seed, REAL_WORLD, draw, n=n) if spec.kind == "real" else derive_seeds(cfg.seed, WORLD, n=n)
        return [episode_task(spec, g["theta"], s, seconds=cfg.seconds, robot=cfg.robot, profile=cfg.profile,
                             stochasticity=cfg.stochasticity,
                             transformer=info["transformer"], identified=info["identified"] or (),
                             key=f"w|{spec.key}|d{draw}|{g['name']}|e{e}")
                for g in gaits for e, s in enumerate(seeds)]

    def run(self) -> dict:
        """Measure everything not measured yet and return (and save) the result."""
        cfg = self.cfg
        self._log = EpisodeLog(self.run_dir, cfg.to_dict(), "fidelity run", ignore=cfg.RESUMABLE, reporter=self.report)
        clock = WallClock(self.run_dir)
        gaits = self.panel()
        self.report.say(f"panel: {len(gaits)} gaits; {cfg.real_trials} real trials each; worlds "
                        f"{', '.join(s.name for s in self.specs)}; {cfg.data_seeds} draws of the real data")
        real_seeds = derive_seeds(cfg.seed, REAL, n=cfg.real_trials)
        with self.phase("real trials"):
            self._log.run(self.ex, [EpisodeTask("real", g["theta"], s, cfg.seconds, robot=cfg.robot, profile=cfg.profile,
                                                stochasticity=cfg.stochasticity,
                                                key=f"real|{g['name']}|t{j}")
                                    for g in gaits for j, s in enumerate(real_seeds)], "real trials")
        prep = prepare_draws(cfg, self.specs, self.run_dir, self.ex, self.report, self.phase, self.data_gait())
        tasks = [t for spec in self.specs for d in (range(cfg.data_seeds) if spec.per_draw else [0])
                 for t in self.world_tasks(spec, d, prep[spec.name][d], gaits)]
        with self.phase("world episodes"):
            self._log.run(self.ex, tasks, "training-world episodes")
        self.replay(prep)
        res = self.result(gaits, prep)
        res["wall_s"] = clock.save()
        res["phases_s"] = self.phases()
        self.write(res)
        return res

    def replay(self, prep: dict) -> None:
        """Teacher-force every grounded world along its draw's real grounding walks
        (:func:`experiments.runtime.tasks.replay_walk_task`: the real next states in place of the forward
        model); the results go to ``replay.json`` in the draw's model directory (resumable) and into
        ``prep`` as ``info["replay"]``. Worlds whose inverse models are the same (``gat`` and ``sgat``
        fitted on the same walks) replay alike, so one of them is walked."""
        todo, first = [], {}
        for s in self.specs:
            if not s.grounded:
                continue
            for d in range(self.cfg.data_seeds):
                info = prep[s.name][d]
                path = os.path.join(info["transformer"], "replay.json")
                if os.path.exists(path):
                    with open(path) as f:
                        info["replay"] = json.load(f)
                    continue
                reports = tuple(info["identified"] or ()) if s.needs_identification else ()
                tasks = [ReplayTask(p, info["transformer"], tuple(info["data_gait"]), self.cfg.seconds, reports,
                                    self.cfg.robot) for p in info["real_paths"]]
                sig = (inverse_signature(info["transformer"]), tuple(info["real_paths"]), reports)
                todo.append((info, path, tasks if sig not in first else None, sig))
                first.setdefault(sig, len(todo) - 1)
        if not todo:
            return
        flat = [t for _, _, tasks, _ in todo if tasks for t in tasks]
        t0 = self.report.elapsed
        self.report.say(f"teacher-forcing {len(flat)} grounding walks ({len(first)} sets of inverse models)")
        with self.phase("teacher forcing"):
            results = iter(self.ex.map(replay_walk_task, flat))
        for info, path, tasks, sig in todo:
            info["replay"] = [dataclasses.asdict(next(results)) for _ in tasks] if tasks else todo[first[sig]][0]["replay"]
            atomic_write_text(path, json.dumps(jsonable(info["replay"]), indent=1))
        self.report.say(f"  teacher-forced ({self.report.elapsed - t0:.0f} s)")

    # ---------------------------------------------------------------- results
    def _matrix(self, prefix: str, gaits, n: int, what: str) -> np.ndarray:
        done = self._log.done
        return np.array([[float(done[f"{prefix}|{g['name']}|{'t' if prefix == 'real' else 'e'}{j}"][what])
                          for j in range(n)] for g in gaits])

    def result(self, gaits, prep) -> dict:
        """The run's result (saved as ``fidelity.json``): the panel, the real trials' figures, every
        world's per-draw scores and summary, the paired tests and, with θ files, the per-group scores."""
        cfg = self.cfg
        R = self._matrix("real", gaits, cfg.real_trials, "fitness")
        F = self._matrix("real", gaits, cfg.real_trials, "fell")
        real_fit, real_fall = R.mean(1), F.mean(1)
        base_rate = float(F.mean())
        out = {"config": cfg.to_dict(), "gaits": [g["name"] for g in gaits],
               "real": {"fitness": real_fit.tolist(), "fitness_se": (R.std(1, ddof=1) / math.sqrt(R.shape[1])).tolist(),
                        "fall_rate": real_fall.tolist(),
                        "speed_cm_s": self._matrix("real", gaits, cfg.real_trials, "speed_cm_s").mean(1).tolist(),
                        "trials": cfg.real_trials, "fitness_trials": R.tolist(), **split_half_reliability(R, seed=cfg.seed),
                        "brier_base_rate": brier_score(np.full(len(gaits), base_rate), F),
                        "brier_own_frequency": brier_score(real_fall, F)},
               "worlds": {s.name: self._world_scores(s, gaits, prep, real_fit, R, F) for s in self.specs}}
        out["paired"] = paired_rows(out, n_boot=cfg.bootstrap, seed=cfg.seed)
        if cfg.params:  # each world on the drawn and the given gaits apart
            out["groups"] = group_rows(out)
        return out

    def _world_scores(self, spec: WorldSpec, gaits, prep, real_fit, R, F) -> dict:
        """One world's entry of the result: its scores per draw, their summary over the draws and the
        same from the first k episodes of every gait (``by_episodes``)."""
        cfg = self.cfg
        draws, curve = [], {}
        n = 1 if spec.deterministic else cfg.episodes
        for d in (range(cfg.data_seeds) if spec.per_draw else [0]):
            pre = f"w|{spec.key}|d{d}"
            W = self._matrix(pre, gaits, n, "fitness")
            WF = self._matrix(pre, gaits, n, "fell")
            wf, wp = W.mean(1), WF.mean(1)
            info = prep[spec.name][d]
            # the world's own episode noise: how well its n-episode means would rank against themselves
            own = split_half_reliability(W, seed=cfg.seed + d) if n >= 2 else None
            for k in episode_counts(n):  # the same figures from the first k episodes of every gait
                curve.setdefault(k, []).append({"draw": d, **draw_metrics(W[:, :k].mean(1), WF[:, :k].mean(1), real_fit, F)})
            draws.append({
                "draw": d, "fitness": wf.tolist(), "fall_rate": wp.tolist(), "fitness_episodes": W.tolist(),
                **draw_metrics(wf, wp, real_fit, F),
                "rho_ci90": list(bootstrap_spearman(wf, R, n_boot=cfg.bootstrap, seed=cfg.seed + d)),
                "world_reliability": None if own is None else own["reliability"],
                "world_ceiling": None if own is None else own["ceiling"],
                "real_walks": info["real_walks"], "real_seconds": info["real_seconds"],
                "real_walk_falls": info.get("real_walk_falls", 0),
                **({"replay": replay_summary(info["replay"])} if info.get("replay") else {}),
                "excitation_logs": info["excitation_logs"], "excitation_seconds": info["excitation_seconds"],
                **({"effects": info.get("effects"), "terrain_rms_height": info.get("terrain_rms_height")}
                   if spec.needs_identification else {}),
                **({"delay": info["delay"]} if info.get("delay") else {}),
            })
        g = spec.grounding_config(delay=0) if spec.grounded else None
        return {"kind": spec.kind, "episodes": n, "deterministic": spec.deterministic, "draws": draws,
                "summary": summary(draws), "grounding": g.to_dict() if g else None,
                **({"by_episodes": {str(k): {"draws": c, "summary": summary(c)} for k, c in curve.items()}} if curve else {})}

    def write(self, res: dict) -> None:
        atomic_write_text(os.path.join(self.run_dir, "fidelity.json"), json.dumps(jsonable(res), indent=1))
        atomic_write_text(os.path.join(self.run_dir, "table.txt"), format_table(res) + "\n")
        plot(res, os.path.join(self.run_dir, "fidelity.png"))
        if len({r["episodes"] for r in episodes_rows(res)}) > 1:
            plot_episodes(res, os.path.join(self.run_dir, "fidelity_episodes.png"))


__all__ = ["Fidelity", "drawn_panel", "inverse_signature"]
