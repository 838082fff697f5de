"""How well does each training world predict the real world? (``sgatwalk fidelity``)

A grounded sim is only worth what it predicts about the real world. For a **panel of gaits** (θ0,
``gaits`` gaits drawn uniformly in the optimizer's trust region of ±``box`` around θ0 in the
normalized space CMA-ES searches, and any θ files given), this measures:

* the **real fitness** of every gait over ``real_trials`` paired real trials (trial j of every gait
  runs on the same seed: the same terrain, effects and noise);
* each **training world's** fitness for the same gaits (the mean over ``episodes`` episodes on seeds
  shared by the gaits; one for a deterministic world: the sim and GAT). Worlds that learn from real
  data are fitted ``data_seeds`` times, each on an independent draw of that data, exactly as
  ``sgatwalk optimize``'s first grounding step fits them (the same code,
  :func:`experiments.runtime.grounding.fit_nao_grounding`, and settings: 4 real and 4 sim walks of θ0,
  α = 0.5, ...).

Worlds (``--worlds``; options after ``:``, e.g. ``sgat:ensemble=5:real=8``):

============  ==========================================================================
``sim``       the plain MuJoCo sim
``ane``       the sim with Gaussian noise on the leg targets (action-noise envelope)
``gat``       grounded, deterministic forward model (GAT)
``sgat``      grounded, stochastic forward model (SGAT)
``identified``  the sim with the physics ``sgatwalk diagnose`` identified from excitation logs
              of the real world (``sysid.identified.IdentifiedSimEnv``), each diagnosis in
              ``--identify-rounds`` screen/refit rounds (``experiments.runtime.grounding.IDENTIFY_ROUNDS``)
``hybrid``    SGAT grounding on top of the identified sim: the transformer learns only what
              the physics library could not name
``oracle``    the real world itself, on fresh seeds per draw and as many episodes per gait as
              the other stochastic worlds: what a training world that is exactly right gets
              with that many episodes (not a default world; it costs real trials);
              ``oracle:mean=1``: the real world with every effect fixed at the middle of its
              range (its terrain amplitude too; the surface stays random): what a world that
              knows the real physics exactly, as one point, gets (the identified sim's best);
              ``oracle:mean=1:engine=mujoco``: that mean physics built into the MuJoCo sim by
              the identified sim's effect models (``experiments.runtime.tasks.mean_physics_report``):
              what the identified world would get if the diagnosis found every effect exactly;
              ``ground=real`` (MuJoCo form) or ``ground=model`` (PyBullet form): the same
              physics on the other engine's ground, the very surface of each episode seed (the
              real world's lumpy terrain, ``envs.bullet_world.real_ground``; the identified sim's
              Gaussian surface, ``sysid.identified.model_ground``): with the two plain forms, a
              2 × 2 of engine and ground that tells the engines' gap from the ground model's;
              ``compliance=S`` and ``backlash=0`` (MuJoCo form): the ground contact's time
              constant the diagnosis identifies (S seconds) and no backlash terms (series play
              hinges), the two settings ``benchmarks/engine_gap_walks.py`` found the form carries;
              ``drop=F+G``: without those effect families (``experiments.runtime.tasks.
              MEAN_PHYSICS_FAMILIES``), what an identified world that misses them loses
============  ==========================================================================

Options of the grounded worlds (``gat``, ``sgat``, ``hybrid``): ``alpha``, ``ensemble``,
``inverse_command`` (0/1), ``residual`` (0/1: sample only the variance the sim does not have),
``matched`` (0/1: a matched transformer, g = a + f_sim^-1(s, ŝ_real) − f_sim^-1(s, ŝ_sim), with a forward
model of the sim fitted on the sim walks), ``zero`` (0/1: linear models fitted from zero weights),
``local`` (0/1: a joint-local inverse model, each joint's command from its own state entries only),
``mixture`` (K: SGAT's forward model a mixture of K Gaussians, a mixture density network),
``memory`` (τ [s]: SGAT's sampling noise correlated over τ, an AR(1) process; 0: white),
``shadow`` (τ [s]: the forward model predicts from a shadow state that relaxes toward the sim's over
τ, so a deviation the sim did not follow persists; 0: the paper), ``dad`` (N: rounds of Data as
Demonstrator for the forward model, fitted also on the states the grounded sim reaches when it replays
the real walks' commands, labelled with the real next states; 0: the paper),
``gate`` (q in (0, 1]: the correction gated by the ensemble's disagreement, shrunk where the members
disagree more than the q-quantile of their disagreement on the real transitions they were fitted on,
:class:`sgat.transformer.ActionTransformer` ``gate_scale``; twenty-third round; 0: the paper),
``hidden`` (e.g. ``128x128``; ``0``: linear models), ``epochs``, ``real`` (real walks per draw), ``sim`` (sim walks),
``noise`` (exploration noise of the sim walks [rad]), ``gaits`` (the walks are spread over θ0 and
``gaits`` - 1 gaits drawn in the box), ``state`` (``legs`` or ``legs+imu``: the grounding state),
``history`` (frames of state the models see), ``commands`` (c: the forward model also sees the c
previous commands, so the transformer can represent an actuation latency); ``method`` (sgat/gat) for ``hybrid``; of ``ane``: ``sigma``;
of ``identified``: ``terms=0`` (only the identified ground) or ``ground=0`` (only the deterministic
effects), to see which part of the identified physics carries its fidelity; of ``identified`` and
``hybrid``: ``stepping`` (stepping logs per identification, default the run's 3; the fixed-base
logs stay the draw's), for fidelity against the amount of excitation data; ``confounded=1``: also
build in the contact terms the diagnosis kept only as uncertain and could not tell apart from the uneven
ground it declared (``sysid.identified.confounded_with_ground``: they count the ground twice); the
default (``confounded=0``) leaves them out since the fourteenth round, and results saved before it
name the world that builds them in plain ``identified`` / ``hybrid`` (:func:`canonical_world_name`);
``walkfit=actuation`` (torque-limit and leg kp scales, latency) or ``walkfit=ground`` (latency and the
RMS height of the uneven ground): those terms fitted to the draw's real walks of θ0, the walks SGAT
is grounded on, by simulated moments of the leg tracking errors and the torso's sway
(:mod:`experiments.runtime.walkfit`; thirteenth round), over the diagnosis's values; ``servo=air`` or
``servo=stepping``: one kp scale common to every servo (``pd_gain_all``) fitted to the draw's
fixed-base (in-air) or stepping logs on top of the diagnosis's model, whether or not the diagnosis's
selection would keep it (:meth:`Fidelity._servo_fits`; fifteenth round); ``servo=staged``: the
in-air fit, then the stepping logs diagnosed again with it under them (bottom-up, as the diagnosis
stages the in-air model under the stepping logs); ``servo=refit``: as ``staged``, with the common kp
fitted jointly with one dry and one viscous friction common to every joint and every term of the
in-air model (the in-air latency had taken up the lag of the joints' friction; sixteenth round).
Of ``gat``, ``sgat``, ``identified`` and ``hybrid``: ``ane`` (σ [rad]: the ANE's Gaussian noise on
the leg targets added to that world's episodes, the training world of ``sgatwalk optimize --methods
sgat+ane``; seventeenth round).

Per world and draw: Spearman ρ between world and real fitness over the gaits (with a 90 % bootstrap
interval over the paired real trials), mean absolute error and bias (world − real) of the fitness,
the Brier score of the world's fall frequency per gait against the real falls, and the regret of
its pick (the real fitness lost by choosing the gait the world rates best, ``stats.pick_regret``:
what optimizing in the world over this panel would cost); and the spread of each over the draws.
Whether one world ranks better than another beyond the noise is a paired test (``paired`` in the
result, :func:`paired_rows`; twenty-third round): the mean over the draws of their ρ difference with
a 90 % interval and a p-value from a bootstrap over the gaits, the real trials and the episodes, for
every world against the plain sim, every variant against its plain kind, and SGAT − GAT, hybrid −
identified and hybrid − SGAT.
The ceiling that the real trials' own noise allows is the square root of their split-half
reliability (``experiments.runtime.stats``); the same figure over a stochastic world's episodes
(``world_ceiling``, per draw) is the ceiling its own episode noise puts on ρ: when it is near 1,
more episodes per gait cannot lift ρ and what is left is the world's model error. Every stochastic
world is also scored from the first k of its episodes per gait, k = 1, 2, 4, ... up to ``episodes``
(``by_episodes``, :func:`episodes_rows`, ``fidelity_episodes.png``): episode seeds are a
prefix-stable stream, so these are the figures a run with ``--episodes k`` reports, and one run
gives fidelity against the number of episodes per gait. A panel with θ files also scores every
world on the drawn gaits and on the given ones apart, and on each file name among the given
(``groups``, :func:`group_rows`; twenty-eighth round): what each world promised for the gaits an
optimizer returned (a run's ``thetas/``) against what they walked. Everything random is keyed by
(seed, purpose, ...) through ``numpy.random.SeedSequence``; a run directory resumes where it stopped.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import math
import os
import time
from dataclasses import dataclass

import numpy as np

from common.defaults import CONTROL_DT, EPISODE_SECONDS
from common.files import WallClock, atomic_path, atomic_write_text, jsonable
from experiments.cli.argtypes import parse_hidden
from experiments.runtime.rundir import EpisodeLog
from experiments.runtime.grounding import (DEFAULT_GROUNDING, DEFAULT_HISTORY, EXPLORATION_NOISE, HYBRID_GROUNDING, IDENTIFY_BUDGET_S,
                                   IDENTIFY_ROUNDS, REAL_WALKS, SIM_WALKS, identified_delay)
from experiments.runtime.identify import (ENGINE_GAP_SEED, calibrate_engines, excitation_tasks, fit_servo_gain,
                                  identify_real, record_excitation_task)
from experiments.runtime.stats import (bootstrap_spearman, brier_score, paired_spearman_difference, pick_regret, spearman,
                               split_half_reliability)
from experiments.runtime.tasks import IDENTIFIED_CONFOUNDED, MEAN_PHYSICS_FAMILIES, fit_grounding_task
from experiments.runtime.walkfit import GRIDS as WALKFIT_GRIDS
from sgat.grounding import GroundingConfig
from robots import ROBOT_NAMES, get_robot
from walk_engine import params_for

#: The ``servo=`` variants (:meth:`Fidelity._servo_fits`): the common servo stiffness fitted to the
#: in-air logs (``air``), the same followed by the stepping diagnosis again on top of it (``staged``),
#: fitted to the stepping logs (``stepping``), or fitted to the in-air logs jointly with the joints'
#: common friction and every term of the in-air model, then the stepping diagnosis again on top
#: (``refit``; sixteenth round).
SERVO_LOGS = ("air", "staged", "stepping", "refit")
#: The ``servo=`` variants whose stepping logs are diagnosed again on top of the in-air fit.
STAGED_SERVO = ("staged", "refit")
#: The ground of each engine's mean-physics oracle (``oracle:mean=1:ground=...``): the real world's lumpy
#: terrain is PyBullet's own, the identified sim's Gaussian surface model the MuJoCo form's own.
OWN_GROUND = {"pybullet": "real", "mujoco": "model"}
#: World kinds (see the module docstring).
KINDS = ("sim", "ane", "gat", "sgat", "identified", "hybrid", "oracle")
DEFAULT_WORLDS = KINDS[:-1]
#: Kinds whose every episode of a gait is the same whatever its seed (:attr:`WorldSpec.deterministic`).
DETERMINISTIC_KINDS = ("sim", "gat")
#: World kinds paired against ``oracle`` (:func:`world_pairs`): every kind but the plain sim and the
#: real world, those that learn from real data or add noise to the sim as stand-ins for the real world.
_LEARNED_KINDS = tuple(k for k in KINDS if k not in ("sim", "oracle"))
#: The phases of a run, in run order, whose wall time ``fidelity.json`` reports (``phases_s``): where a
#: run's time goes (the README's default run: the diagnoses and the world episodes, on busy cores).
PHASES = ("real trials", "excitation logs", "diagnoses", "servo fits", "grounding walks", "walk fits", "fits",
          "world episodes", "teacher forcing")
#: Purposes of the seed streams (the first key after the run seed). ``_CAL`` drew the engine-gap
#: calibration's seed until that became one constant (``experiments.runtime.identify.ENGINE_GAP_SEED``, seed
#: 0's draw); it keeps its place so the streams after it keep their values.
_PANEL, _REAL, _GROUND_REAL, _GROUND_SIM, _WORLD, _FIT, _IDENT, _CAL, _DATA_GAITS, _ORACLE, _WALKFIT = range(11, 22)


def drawn_panel(params_class, seed: int, gaits: int, box: float) -> list[dict]:
    """The drawn part of a fidelity panel: θ0 and ``gaits`` gaits drawn uniformly in ±``box`` around it
    in the normalized space CMA-ES searches (clipped to [0, 1]), from the run seed's panel stream:
    ``[{"name": "theta0" | "boxNN", "theta": [16 SI values]}]`` (what ``sgatwalk fidelity --seed``
    walks; ``params_class`` a :func:`walk_engine.params_for` class)."""
    th0 = params_class.initial()
    u0 = th0.to_vector()
    rng = np.random.default_rng(np.random.SeedSequence([seed, _PANEL]))
    out = [{"name": "theta0", "theta": th0.to_array().tolist()}]
    for i in range(gaits):
        u = np.clip(u0 + rng.uniform(-box, box, len(u0)), 0.0, 1.0)
        out.append({"name": f"box{i:02d}", "theta": params_class.from_vector(u).to_array().tolist()})
    return out


def _seeds(seed: int, purpose: int, *keys: int, n: int) -> list[int]:
    """``n`` seeds keyed by (seed, purpose, keys) (``numpy.random.SeedSequence.generate_state``): the
    first k of n are the k seeds asked for with ``n=k``, so a run resumed with more episodes per gait
    adds episodes to those it has."""
    return [int(s) for s in np.random.SeedSequence([seed, purpose, *keys]).generate_state(n, dtype=np.uint32)]


# ------------------------------------------------------------------------------------------ worlds
#: WorldSpec fields added after the first release, with their defaults then (left out of the cache key).
#: ``identified_confounded`` keeps True here though the field's default is False since the fourteenth
#: round: a default world hashes as ``confounded=0`` did and ``confounded=1`` as the old default did, so
#: every cached world keeps its meaning.
_LATER_OPTIONS = {"identified_terms": True, "identified_ground": True, "state": "legs", "history": 1,
                  "stepping_logs": None, "identified_confounded": True, "oracle_mean": False, "walkfit": "",
                  "oracle_engine": "pybullet", "servo": "", "envelope": 0.0, "delay_auto": False, "oracle_ground": "",
                  "oracle_compliance": 0.0, "oracle_backlash": True, "oracle_drop": ""}


@dataclass(frozen=True)
class WorldSpec:
    """One training world: its name (as given), kind, grounding settings and data per draw."""

    name: str
    kind: str
    grounding: object = None  # sgat.grounding.GroundingConfig for gat / sgat / hybrid
    real_walks: int = REAL_WALKS
    sim_walks: int = SIM_WALKS
    exploration_noise: float = EXPLORATION_NOISE
    data_gaits: int = 1
    sigma: float = 0.05  # ane
    state: str = "legs"  # grounding state (experiments.runtime.grounding.nao_spec)
    history: int | None = None  # frames of state history the models see (None: DEFAULT_HISTORY if grounded, else 1)
    identified_terms: bool = True  # identified: the deterministic effects (ablation switch)
    identified_ground: bool = True  # identified: the uneven ground (ablation switch)
    stepping_logs: int | None = None  # identified / hybrid: stepping logs per identification (None: the run's)
    identified_confounded: bool = IDENTIFIED_CONFOUNDED  # identified / hybrid: build in contact terms confounded with the ground
    oracle_mean: bool = False  # oracle: the real world with its effects fixed at their mean (experiments.runtime.tasks.mean_profile)
    walkfit: str = ""  # identified / hybrid: terms fitted to the real walks of θ0 (a grid of experiments.runtime.walkfit.GRIDS)
    oracle_engine: str = "pybullet"  # oracle:mean=1: the engine its mean physics runs in (mujoco: the identified sim)
    servo: str = ""  # identified / hybrid: a kp scale common to every servo (one of SERVO_LOGS; "": none)
    envelope: float = 0.0  # gat / sgat / identified / hybrid: the ANE's noise [rad] added to the world's leg targets
    delay_auto: bool = False  # hybrid: the models bridge the draw's identified latency (experiments.runtime.grounding.identified_delay)
    oracle_ground: str = ""  # oracle:mean=1: its ground, a value of OWN_GROUND (default: its engine's own)
    oracle_compliance: float = 0.0  # oracle:mean=1:engine=mujoco: the ground contact's time constant [s] (0: the sim's)
    oracle_backlash: bool = True  # oracle:mean=1:engine=mujoco: build the backlash terms (series play hinges)
    oracle_drop: str = ""  # oracle:mean=1:engine=mujoco: effect families left out, sorted and joined by "+"

    def __post_init__(self) -> None:
        if self.history is None:
            object.__setattr__(self, "history", DEFAULT_HISTORY if self.grounded else 1)

    @property
    def key(self) -> str:
        """The world's cache key: its kind and a hash of every setting (a changed default is a new world)."""
        d = dataclasses.asdict(self)
        d.pop("name")
        if not self.needs_identification:  # a setting of the identified worlds only: it names no other world
            d["identified_confounded"] = _LATER_OPTIONS["identified_confounded"]
        if self.oracle_ground == OWN_GROUND[self.oracle_engine]:  # the engine's own ground: the plain world
            d["oracle_ground"] = _LATER_OPTIONS["oracle_ground"]
        for k in _LATER_OPTIONS:  # options added later hash only when set, so earlier caches stay valid
            if d[k] == _LATER_OPTIONS[k]:
                d.pop(k)
        d["grounding"] = self.grounding.to_dict() if self.grounding else None
        return f"{self.kind}-{hashlib.sha1(json.dumps(d, sort_keys=True).encode()).hexdigest()[:10]}"

    @property
    def servo_fit(self) -> str:
        """This world's fit of the common servo stiffness (:meth:`Fidelity._servo_fits`): ``"stepping"``
        (to the stepping logs), ``"air"`` (to the in-air logs: ``servo=air`` and ``servo=staged``),
        ``"air_refit"`` (to the in-air logs, jointly with the in-air model's terms: ``servo=refit``) or
        ``""`` (no ``servo=`` option)."""
        return {"": "", "stepping": "stepping", "refit": "air_refit"}.get(self.servo, "air")

    @property
    def grounded(self) -> bool:
        return self.kind in ("gat", "sgat", "hybrid")

    @property
    def needs_identification(self) -> bool:
        return self.kind in ("identified", "hybrid")

    @property
    def deterministic(self) -> bool:
        """Whether every episode of a gait is the same whatever its seed, so one episode per gait is
        the world's answer: the sim (MuJoCo is deterministic) and GAT on it (deterministic models, an
        ensemble's members averaged: ``sgat.ActionTransformer.transform``). ``tests/test_fidelity.py``
        checks it on episodes with different seeds."""
        return self.kind in DETERMINISTIC_KINDS and not self.envelope

    @property
    def per_draw(self) -> bool:
        """Fitted on real data: one world per draw of that data (the oracle: one set of fresh real
        seeds per draw)."""
        return self.grounded or self.needs_identification or self.kind == "oracle"


def parse_world(text: str) -> WorldSpec:
    """A world from ``kind[:key=value...]`` (module docstring).

    Raises:
        ValueError: unknown kind or option, or a bad value (named).
    """
    parts = [p.strip() for p in str(text).split(":")]
    kind = parts[0]
    if kind not in KINDS:
        raise ValueError(f"unknown world {kind!r}; choose from {', '.join(KINDS)} (options after ':')")
    g = HYBRID_GROUNDING if kind == "hybrid" else dataclasses.replace(DEFAULT_GROUNDING, method=kind) \
        if kind in ("sgat", "gat") else None
    kw: dict = {}
    gkw: dict = {}
    for opt in parts[1:]:
        if "=" not in opt:
            raise ValueError(f"world {text!r}: option {opt!r} is not key=value")
        k, v = (s.strip() for s in opt.split("=", 1))
        try:
            if kind == "ane" and k == "sigma":
                kw["sigma"] = float(v)
            elif kind == "identified" and k in ("terms", "ground"):
                kw[f"identified_{k}"] = bool(int(v))
            elif kind in ("identified", "hybrid") and k == "stepping":
                kw["stepping_logs"] = int(v)
            elif kind in ("identified", "hybrid") and k == "confounded":
                kw["identified_confounded"] = bool(int(v))
            elif kind in ("identified", "hybrid") and k == "walkfit":
                if v not in (*WALKFIT_GRIDS, "0"):
                    raise ValueError(f"world {text!r}: unknown option value walkfit={v!r} "
                                     f"({' or '.join(WALKFIT_GRIDS)}; 0: none)")
                kw["walkfit"] = "" if v == "0" else v
            elif kind in ("identified", "hybrid") and k == "servo":
                if v not in (*SERVO_LOGS, "0"):
                    raise ValueError(f"world {text!r}: unknown option value servo={v!r} "
                                     f"({' or '.join(SERVO_LOGS)}; 0: none)")
                kw["servo"] = "" if v == "0" else v
            elif kind in ("gat", "sgat", "identified", "hybrid") and k == "ane":
                kw["envelope"] = float(v)
                if not (np.isfinite(kw["envelope"]) and kw["envelope"] >= 0):
                    raise ValueError(v)  # reported as a bad value of ane below
            elif kind == "oracle" and k == "mean":
                kw["oracle_mean"] = bool(int(v))
            elif kind == "oracle" and k == "engine":
                if v not in ("pybullet", "mujoco"):
                    raise ValueError(f"world {text!r}: unknown option value engine={v!r} (pybullet or mujoco)")
                kw["oracle_engine"] = v
            elif kind == "oracle" and k == "compliance":
                kw["oracle_compliance"] = float(v)
                if not (np.isfinite(kw["oracle_compliance"]) and kw["oracle_compliance"] > 0):
                    raise ValueError(v)  # reported as a bad value of compliance below
            elif kind == "oracle" and k == "backlash":
                kw["oracle_backlash"] = bool(int(v))
            elif kind == "oracle" and k == "drop":
                fams = sorted(set(v.split("+")))
                if "backlash" in fams or set(fams) - set(MEAN_PHYSICS_FAMILIES):
                    raise ValueError(f"world {text!r}: unknown option value drop={v!r} (families joined by +, of "
                                     f"{', '.join(f for f in MEAN_PHYSICS_FAMILIES if f != 'backlash')}; "
                                     "backlash: backlash=0)")
                kw["oracle_drop"] = "+".join(fams)
            elif kind == "oracle" and k == "ground":
                if v not in OWN_GROUND.values():
                    raise ValueError(f"world {text!r}: unknown option value ground={v!r} ({' or '.join(OWN_GROUND.values())})")
                kw["oracle_ground"] = v
            elif kind in ("gat", "sgat", "hybrid") and k in ("alpha", "ensemble", "inverse_command", "hidden", "epochs",
                                                              "real", "sim", "noise", "residual", "method", "mixture", "memory", "shadow",
                                                              "gaits", "state", "history", "commands", "matched",
                                                              "zero", "local", "dad", "gate", "delay"):
                if k == "method" and kind == "hybrid" and v in ("sgat", "gat"):
                    gkw["method"] = v
                elif k == "method":
                    raise ValueError(f"world {text!r}: unknown option {k!r} for {kind} (hybrid takes method=sgat|gat)")
                elif k == "gaits":
                    kw["data_gaits"] = int(v)
                elif k == "state":
                    if v not in ("legs", "legs+imu"):
                        raise ValueError(f"world {text!r}: unknown option value state={v!r} (legs or legs+imu)")
                    kw["state"] = v
                elif k == "history":
                    kw["history"] = int(v)
                elif k == "mixture":
                    gkw["components"] = int(v)
                elif k == "commands":
                    gkw["command_history"] = int(v)
                elif k == "delay":  # control steps, or auto: the draw's identified latency (hybrid)
                    if v == "auto":
                        if kind != "hybrid":
                            raise ValueError(f"world {text!r}: unknown option value delay=auto for {kind} "
                                             "(the identified latency: hybrid only)")
                        kw["delay_auto"] = True
                    else:
                        gkw["delay"] = int(v)
                elif k == "memory":  # seconds -> control steps
                    gkw["noise_memory"] = float(v) / CONTROL_DT
                elif k == "shadow":  # seconds -> control steps
                    gkw["shadow_memory"] = float(v) / CONTROL_DT
                elif k == "residual":
                    gkw["residual_noise"] = bool(int(v))
                elif k == "matched":
                    gkw["matched"] = bool(int(v))
                elif k == "zero":
                    gkw["zero_init"] = bool(int(v))
                elif k == "local":
                    gkw["local_inverse"] = bool(int(v))
                elif k == "dad":
                    gkw["dad_iterations"] = int(v)
                elif k == "gate":
                    gkw["gate"] = float(v)
                elif k == "alpha":
                    gkw["alpha"] = float(v)
                elif k == "ensemble":
                    gkw["ensemble"] = int(v)
                elif k == "inverse_command":
                    gkw["inverse_command"] = bool(int(v))
                elif k == "hidden":
                    gkw["hidden"] = parse_hidden(v)  # 0: linear models
                elif k == "epochs":
                    gkw["max_epochs"] = int(v)
                elif k == "real":
                    kw["real_walks"] = int(v)
                elif k == "sim":
                    kw["sim_walks"] = int(v)
                else:
                    kw["exploration_noise"] = float(v)
            else:
                raise ValueError(f"world {text!r}: unknown option {k!r} for {kind}")
        except ValueError as exc:
            if "unknown option" in str(exc):
                raise
            raise ValueError(f"world {text!r}: bad value for {k}: {v!r}") from None
    for k in ("real_walks", "sim_walks", "data_gaits", "history"):
        if kw.get(k, 1) < 1:
            raise ValueError(f"world {text!r}: {k} must be >= 1")
    if kw.get("stepping_logs", 0) < 0:
        raise ValueError(f"world {text!r}: stepping must be >= 0 (stepping logs per identification)")
    if kw.get("oracle_engine") == "mujoco" and not kw.get("oracle_mean"):
        raise ValueError(f"world {text!r}: engine=mujoco builds the real world's mean physics into the sim: "
                         "it needs mean=1")
    if {"oracle_compliance", "oracle_backlash", "oracle_drop"} & set(kw) and kw.get("oracle_engine") != "mujoco":
        raise ValueError(f"world {text!r}: compliance=, backlash= and drop= set the MuJoCo form of the mean physics: "
                         "they need mean=1:engine=mujoco")
    if kw.get("oracle_ground") and not kw.get("oracle_mean"):
        raise ValueError(f"world {text!r}: ground= walks the real world's mean physics on a given ground: it needs mean=1")
    if kw.get("oracle_mean"):  # the mean oracles name their ground: the engine's own unless given
        kw.setdefault("oracle_ground", OWN_GROUND[kw.get("oracle_engine", "pybullet")])
    if kw.get("exploration_noise", 0) < 0 or kw.get("sigma", 0) < 0:
        raise ValueError(f"world {text!r}: noise levels must be >= 0")
    grounding = GroundingConfig(**{**dataclasses.asdict(g), **gkw}) if g is not None else None
    return WorldSpec(name=str(text), kind=kind, grounding=grounding, **kw)


def canonical_world_name(name: str, world: dict) -> str:
    """A world's name in today's meaning of the options, for results saved by any round.

    Up to the thirteenth round ``identified`` and ``hybrid`` built in the contact terms confounded
    with the uneven ground (today ``confounded=1``) and ``confounded=0`` left them out (today the
    default); results since then record the setting (``identified_confounded`` of the world). The
    name keeps its other options in their order, drops any ``confounded=`` option and ends with
    ``:confounded=1`` where the world builds those terms in; other kinds' names are returned as they
    are. ``sgatwalk compare`` ranks worlds of old and new results by this name.

    Args:
        name: the world's name as its run gave it (``hybrid:alpha=0.5:confounded=0``).
        world: its entry of the result's ``worlds`` (``kind``, and ``identified_confounded`` since
            the fourteenth round).

    Returns:
        e.g. ``"hybrid:alpha=0.5"`` (confounded terms left out) or ``"identified:confounded=1"``.
    """
    kind, *opts = [p.strip() for p in str(name).split(":")]
    if world.get("kind", kind) not in ("identified", "hybrid"):
        return name
    pairs = [(p.split("=", 1)[0].strip(), p) for p in opts]
    given = [p.split("=", 1)[1].strip() for k, p in pairs if k == "confounded" and "=" in p]
    # saved before the fourteenth round: the old default (True) unless the name said confounded=0
    confounded = bool(world["identified_confounded"]) if "identified_confounded" in world \
        else (bool(int(given[-1])) if given else True)
    return ":".join([kind, *(p for k, p in pairs if k != "confounded"), *(["confounded=1"] if confounded else [])])


# ------------------------------------------------------------------------------------------ config
def distinct_suffixes(parts: list[list[str]]) -> list[str]:
    """Per path (given as its components), the shortest trailing part, joined with ``/``, that no
    other path of ``parts`` ends in (the whole path where none is shorter)."""
    names = []
    for i, ps in enumerate(parts):
        for k in range(1, len(ps) + 1):
            name = "/".join(ps[-k:])
            if all("/".join(q[-k:]) != name for j, q in enumerate(parts) if j != i):
                break
        names.append(name)
    return names


def param_gait_names(paths) -> list[str]:
    """Panel names of the θ files ``paths``: each file's name without its extension, or, where two
    files share it (``table1/opt_seed0/thetas/sgat_step1.json`` and ``.../opt_seed1/...``), the
    shortest trailing part of their paths that tells them apart (``opt_seed0/thetas/sgat_step1``).
    Names key the cached trials, so two gaits must never share one.

    Raises:
        ValueError: the same file given twice, or a name that clashes with ``theta0``/``boxNN``.
    """
    parts = [os.path.normpath(os.path.splitext(p)[0]).split(os.sep) for p in paths]
    real = [os.path.realpath(p) for p in paths]
    if len(set(real)) != len(real):
        raise ValueError(f"params: the same θ file is given twice: {sorted({p for p, r in zip(paths, real) if real.count(r) > 1})}")
    names = distinct_suffixes(parts)
    for name in names:
        if name == "theta0" or (name.startswith("box") and name[3:].isdigit()):
            raise ValueError(f"params: the gait name {name!r} clashes with the panel's own gaits; rename the file")
    return names


#: The diagnoses' rounds of every run saved before ``identify_rounds`` existed (its config leaves it out).
_ROUNDS_BEFORE = 2


@dataclass
class FidelityConfig:
    """Settings of a fidelity run (written to ``config.json``)."""

    worlds: tuple = DEFAULT_WORLDS
    gaits: int = 15
    box: float = 0.15
    params: tuple = ()
    real_trials: int = 10
    data_seeds: int = 5
    episodes: int = 8  # per gait in a stochastic world; 4 until the thirty-first round (its fidelity against episodes)
    seconds: float = EPISODE_SECONDS
    profile: str = "real"
    identify_fixed_logs: int = 3
    identify_floating_logs: int = 3
    identify_seconds: float = 6.0
    #: wall-clock time budget of each diagnosis [s], a safety net (``experiments.runtime.grounding.IDENTIFY_BUDGET_S``
    #: says why). Not part of the run's identity: a resumed run keeps the identifications it made.
    identify_budget_s: float = IDENTIFY_BUDGET_S
    #: screen/refit rounds of each diagnosis (``experiments.runtime.grounding.IDENTIFY_ROUNDS`` says why two);
    #: part of the run's identity (runs saved before the setting existed made two, and their config
    #: leaves it out, as :meth:`to_dict` does at two)
    identify_rounds: int = IDENTIFY_ROUNDS
    bootstrap: int = 1000
    seed: int = 0
    robot: str = "nao"

    def validate(self) -> list[WorldSpec]:
        """The parsed worlds; raises ValueError naming the bad setting."""
        if self.robot not in ROBOT_NAMES:
            raise ValueError(f"unknown robot {self.robot!r}; choose from {', '.join(ROBOT_NAMES)}")
        for name in ("real_trials", "data_seeds", "episodes", "bootstrap"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if self.real_trials < 2:
            raise ValueError("real_trials must be >= 2 (the ceiling needs a split-half reliability)")
        if self.gaits < 0:
            raise ValueError(f"gaits must be >= 0, got {self.gaits}")
        param_gait_names(self.params)  # raises on a repeated file or a clashing name
        if 1 + self.gaits + len(self.params) < 3:
            raise ValueError("the panel needs at least 3 gaits for a rank correlation")
        if not (0 < self.box <= 1):
            raise ValueError(f"box must be in (0, 1] (normalized half-width), got {self.box}")
        if not (self.seconds > 0 and math.isfinite(self.seconds)):
            raise ValueError(f"seconds must be positive, got {self.seconds}")
        if self.seed < 0:
            raise ValueError(f"seed must be >= 0, got {self.seed}")
        if not 1 <= int(self.identify_rounds) <= 100:
            raise ValueError(f"identify_rounds must be in 1..100 (screen/refit rounds per diagnosis), got {self.identify_rounds}")
        if self.identify_fixed_logs < 2 or self.identify_floating_logs < 0:
            raise ValueError("identification needs >= 2 fixed-base logs (a held-out split) and >= 0 stepping logs")
        specs = [parse_world(w) for w in self.worlds]
        if self.robot != "nao" and any(sp.kind in ("identified", "hybrid") for sp in specs):
            raise ValueError("the identified and hybrid worlds model the NAO only (sgatwalk diagnose identifies the NAO)")
        names = [s.name for s in specs]
        if not specs or len(set(names)) != len(names) or len({s.key for s in specs}) != len(specs):
            raise ValueError(f"worlds must be a non-empty list without repeats (also under other names), got {names}")
        return specs

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["worlds"], d["params"] = list(self.worlds), list(self.params)
        if d["robot"] == "nao":  # runs from before --robot keep their config
            del d["robot"]
        if d["identify_rounds"] == _ROUNDS_BEFORE:  # ... and runs from before --identify-rounds
            del d["identify_rounds"]
        return d

    @property
    def params_class(self):
        """The robot's :class:`walk_engine.GaitParams` class (``walk_engine.params_for``)."""
        return params_for(get_robot(self.robot))

    def task_robot(self) -> dict:
        """What every episode task of this run carries about the robot (nothing for the NAO)."""
        return {} if self.robot == "nao" else {"robot": self.robot}


# ------------------------------------------------------------------------------------------ run
class Fidelity:
    """Runs (or resumes) a fidelity measurement in ``run_dir`` with ``executor``.

    Files: ``config.json``, ``panel.json`` (the gaits), ``episodes.jsonl`` (one line per finished
    episode, appended as batches finish), ``data/`` (grounding walks), ``models/`` (transformers per
    world and draw), ``identified/`` (excitation logs and diagnoses), ``fidelity.json`` (the result),
    ``fidelity.png``, ``fidelity_episodes.png`` (fidelity against episodes per gait, where a
    stochastic world has more than one), ``table.txt``, ``timing.json`` (wall time of every
    invocation so far) and ``phases.json`` (its split over :data:`PHASES`).
    """

    def __init__(self, cfg: FidelityConfig, run_dir: str, executor, *, log=None, progress: bool = False):
        self.cfg, self.run_dir, self.ex = cfg, run_dir, executor
        self._queued_walks: dict[str, tuple[str, dict]] = {}  # path -> (tag, episode task) to record
        self.specs = cfg.validate()
        self.log = log or (lambda s: None)
        self.progress = progress
        self.t0 = time.perf_counter()
        os.makedirs(run_dir, exist_ok=True)
        self._episodes: dict[str, dict] = {}
        self._phases_path = os.path.join(run_dir, "phases.json")
        try:
            with open(self._phases_path) as f:
                self._phases = {k: float(v) for k, v in json.load(f).items() if k in PHASES}
        except (OSError, ValueError, AttributeError):  # none yet, or unreadable: count from here
            self._phases = {}

    # ---------------------------------------------------------------- bookkeeping
    def _say(self, msg: str) -> None:
        self.log(f"[fidelity {time.perf_counter() - self.t0:7.1f} s] {msg}")

    @contextlib.contextmanager
    def _phase(self, name: str):
        """Add the wall time of the block to phase ``name`` of :data:`PHASES` (accumulated over the
        invocations of the run in ``phases.json``, as ``timing.json`` accumulates the total)."""
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self._phases[name] = self._phases.get(name, 0.0) + time.perf_counter() - t0
            atomic_write_text(self._phases_path, json.dumps(self._phases))

    def phases(self) -> dict[str, float]:
        """Seconds spent in each phase of :data:`PHASES` so far, every invocation included, in run order."""
        return {k: self._phases[k] for k in PHASES if k in self._phases}

    def _check_config(self) -> None:
        """Claim the run directory (``experiments.runtime.rundir.EpisodeLog``); more worlds, more or fewer
        episodes per gait, a new bootstrap or another identification time budget reuse what was
        measured (a world's episode seeds are a prefix-stable stream, :func:`_seeds`: the first k of
        n are the k of a run with k episodes)."""
        self._log = EpisodeLog(self.run_dir, self.cfg.to_dict(), "fidelity run",
                               ignore=("worlds", "episodes", "bootstrap", "identify_budget_s"), say=self._say)
        self._episodes = self._log.done

    def _run(self, tasks: list[dict], desc: str) -> None:
        """Run the tasks whose keys have no result yet (resumable, progress on stderr)."""
        self._log.run(self.ex, tasks, desc, progress=self.progress)

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

    # ---------------------------------------------------------------- grounding data and models
    def _data_gaits(self, n: int, draw: int) -> list[list[float]]:
        """The gaits grounding walks are made with: θ0, and ``n - 1`` gaits drawn in the box (their
        own seed stream, not the panel's)."""
        P = self.cfg.params_class
        u0 = P.initial().to_vector()
        rng = np.random.default_rng(np.random.SeedSequence([self.cfg.seed, _DATA_GAITS, draw]))
        us = [u0] + [np.clip(u0 + rng.uniform(-self.cfg.box, self.cfg.box, len(u0)), 0, 1) for _ in range(n - 1)]
        return [P.from_vector(u).to_array().tolist() for u in us]

    def _walks(self, world: str, seeds: list[int], tag: str, thetas: list, **kw) -> list[str]:
        """The paths of the recordings in ``world`` on ``seeds`` under ``data/`` (cached), walk j
        with gait ``thetas[j % len(thetas)]``; those not recorded yet are queued for
        :meth:`_record_walks`, which records every queued walk in one go."""
        paths = [os.path.join(self.run_dir, "data", f"{tag}_{s}.parquet") for s in seeds]
        for j, (s, p) in enumerate(zip(seeds, paths)):
            if not os.path.exists(p):
                self._queued_walks.setdefault(p, (tag, {
                    "world": world, "theta": thetas[j % len(thetas)], "seed": s, "seconds": self.cfg.seconds,
                    "profile": self.cfg.profile, "record": True, **self.cfg.task_robot(), **kw}))
        return paths

    def _record_walks(self) -> None:
        """Record the walks :meth:`_walks` queued, all worlds and draws in one map on the executor
        (each walk carries its own seed: the same recordings as one world at a time)."""
        from envs import Recording  # lazy: loads the engines
        from experiments.runtime.batch import map_episodes  # lazy: loads the engines

        todo, self._queued_walks = list(self._queued_walks.items()), {}
        if not todo:
            return
        t0 = time.perf_counter()
        tags = list(dict.fromkeys(tag for _, (tag, _) in todo))
        self._say(f"recording {len(todo)} grounding walks ({', '.join(tags)})")
        with self._phase("grounding walks"):
            for (p, _), r in zip(todo, map_episodes(self.ex, [t for _, (_, t) in todo])):
                Recording(*r["recording"]).to_parquet(p)
        self._say(f"  recorded ({time.perf_counter() - t0:.0f} s)")

    def _stepping(self, spec: WorldSpec) -> int:
        """Stepping logs of ``spec``'s identifications (its ``stepping`` option or the run's)."""
        return self.cfg.identify_floating_logs if spec.stepping_logs is None else spec.stepping_logs

    def _identify_args(self, draw: int, stepping: int) -> dict:
        """Where and from what draw ``draw``'s identification with ``stepping`` stepping logs records
        (the arguments :func:`identify_real` and :func:`excitation_tasks` share): every count shares
        the draw's fixed-base stage (the same logs in the air), so only the stepping stage differs."""
        cfg = self.cfg
        root = os.path.join(self.run_dir, "identified", f"d{draw}")
        return {"out_dir": root if stepping == cfg.identify_floating_logs else f"{root}_stepping{stepping}",
                "seed": _seeds(cfg.seed, _IDENT, draw, n=1)[0] % 1_000_000, "profile": cfg.profile,
                "n_fixed": cfg.identify_fixed_logs, "n_floating": stepping, "seconds": cfg.identify_seconds,
                "fixed_dir": os.path.join(root, "fixed")}

    def _identify(self, draw: int, stepping: int, base_terms: dict | None = None, suffix: str = "") -> dict:
        """Draw ``draw``'s identification from ``stepping`` stepping logs (:meth:`_identify_args`; with
        ``base_terms`` under the stepping diagnosis, in the folder with ``suffix`` added). The
        stepping diagnosis's time budget grows with its logs (``--identify-budget`` per 3 logs):
        with the budget of 3 logs, 2 of 3 diagnoses of 9 logs ran out before the uneven-ground stage
        and left the ground out."""
        cfg = self.cfg
        args = self._identify_args(draw, stepping)
        args["out_dir"] += suffix
        return identify_real(**args, calibration=self._calibration, time_budget_s=cfg.identify_budget_s,
                             rounds=cfg.identify_rounds,
                             stepping_budget_s=cfg.identify_budget_s * max(1.0, stepping / max(1, cfg.identify_floating_logs)),
                             base_terms=base_terms, progress=None)

    def _record_excitation(self, counts: list[int]) -> None:
        """Record the excitation logs of every identification still to be made side by side on the
        executor (one recording per core; the diagnoses that follow keep the cores busy themselves)."""
        todo, seen = [], set()
        for d in range(self.cfg.data_seeds):
            for n in counts:
                for t in excitation_tasks(**self._identify_args(d, n)):
                    if t["out_dir"] not in seen:  # the counts share the fixed-base stage
                        seen.add(t["out_dir"])
                        todo.append(t)
        if not todo:
            return
        t0 = time.perf_counter()
        self._say(f"recording {len(todo)} sets of excitation logs ({sum(t['n_logs'] for t in todo)} logs)")
        with self._phase("excitation logs"):
            list(self.ex.map(record_excitation_task, todo))
        self._say(f"  recorded ({time.perf_counter() - t0:.0f} s)")

    def _walk_fits(self, idents: dict) -> dict:
        """The terms of every walk-fitted identified world (``walkfit=GRID``), per draw: fitted to the
        draw's real grounding walks of θ0, the walks SGAT's grounding of the same draw is fitted on
        (:func:`experiments.runtime.walkfit.fit_walk_terms`), cached under ``identified/d<draw>/walkfit_<GRID>*``.

        Returns:
            ``{(draw, stepping logs, confounded, real walks, grid): {"path": its report, "real_paths": [...]}}``.
        """
        from envs import Recording  # lazy: loads the engines
        from experiments.runtime.walkfit import SIM_WALKS as FIT_WALKS, describe_terms, fit_walk_terms  # lazy: loads the engines

        cfg = self.cfg
        want = sorted({(self._stepping(s), s.identified_confounded, s.real_walks, s.walkfit) for s in self.specs if s.walkfit})
        if not want:
            return {}
        theta0 = self._data_gaits(1, 0)[0]
        real = {(d, n): self._walks("real", _seeds(cfg.seed, _GROUND_REAL, d, n=n), f"real_d{d}", [theta0])
                for d in range(cfg.data_seeds) for _, _, n, _ in want}
        self._record_walks()
        out = {}
        for d in range(cfg.data_seeds):
            for stepping, conf, n, grid in want:
                odir = os.path.join(self._identify_args(d, stepping)["out_dir"],
                                    f"walkfit_{grid}" + ("" if conf else "x") + ("" if n == REAL_WALKS else f"_r{n}"))
                t0 = time.perf_counter()
                with self._phase("walk fits"):
                    fit = fit_walk_terms([Recording.from_parquet(p) for p in real[d, n]], idents[d, stepping]["reports"],
                                             theta0, odir, self.ex, seeds=_seeds(cfg.seed, _WALKFIT, d, n=FIT_WALKS),
                                             seconds=cfg.seconds, grid=grid, identified_confounded=conf)
                self._say(f"walk fit ({grid}) draw {d}: {describe_terms(fit['terms'])} ({time.perf_counter() - t0:.0f} s)")
                out[d, stepping, conf, n, grid] = {"path": fit["path"], "real_paths": real[d, n]}
        return out

    def _servo_fits(self, idents: dict) -> dict:
        """The common servo stiffness of every ``servo=`` world, per draw: one kp scale for every joint
        (``pd_gain_all``) fitted to the draw's fixed-base (``air``: over the in-air diagnosis's model)
        or stepping logs (``stepping``: over the whole identified model) by
        :func:`experiments.runtime.identify.fit_servo_gain` (the refit alone, no screening or selection: the
        diagnosis does not keep the term, whose removal changes its held-out cost by less than its
        margin; ``air_refit``: jointly with every term of the in-air model), written as a report that
        overrides the diagnosis (``identified/d<draw>/servo_*``).

        Returns:
            ``{(draw, stepping logs, confounded, servo fit): report path}`` (the fit as
            :attr:`WorldSpec.servo_fit` names it).

        Raises:
            ValueError: a ``servo=stepping`` world with no stepping logs (``stepping=0``).
        """
        want = sorted({(self._stepping(s), s.identified_confounded, s.servo_fit) for s in self.specs if s.servo})
        out = {}
        for d in range(self.cfg.data_seeds):
            for stepping, conf, which in want:
                args = self._identify_args(d, stepping)
                if which != "stepping":  # the draw's one fixed-base stage, whatever the stepping logs
                    reports = [os.path.join(args["fixed_dir"], "report.json")]
                    logs, cal = os.path.join(args["fixed_dir"], "logs"), self._calibration.get("fixed")
                    path = os.path.join(os.path.dirname(args["fixed_dir"]), f"servo_{which}", "report.json")
                else:
                    if stepping < 1:
                        raise ValueError("servo=stepping needs stepping logs (stepping >= 1)")
                    reports = idents[d, stepping]["reports"]
                    logs, cal = os.path.join(args["out_dir"], "floating", "logs"), self._calibration.get("floating")
                    path = os.path.join(args["out_dir"], "servo_fit" + ("" if conf else "x"), "report.json")
                if not os.path.exists(path):
                    t0 = time.perf_counter()
                    with self._phase("servo fits"):
                        v = fit_servo_gain(reports, logs, cal, path, confounded=conf, refit=which == "air_refit")
                    from sysid.candidates import FAMILIES  # lazy: loads the engines

                    moved = "".join(f", {k} {FAMILIES[k].fmt(a)} -> {FAMILIES[k].fmt(b)}"
                                    for k, (a, b) in v.get("refitted", {}).items()
                                    if k in ("latency", "coulomb_friction_all", "viscous_damping_all"))
                    self._say(f"servo fit ({which}) draw {d}: kp x{v['value']:.3f}{moved} (held-out cost "
                              f"{v['heldout_cost_before']:.0f} -> {v['heldout_cost_after']:.0f}; {time.perf_counter() - t0:.0f} s)")
                out[d, stepping, conf, which] = path
        return out

    def _staged(self, servofits: dict) -> dict:
        """The identifications of every ``servo=staged`` and ``servo=refit`` world, per draw: the draw's
        stepping logs diagnosed again (:func:`identify_real` with the in-air servo fit of
        :meth:`_servo_fits` under them, ``base_terms``) in ``identified/d<draw>_servo`` (``refit``:
        ``_servorefit``; the fixed-base stage is the draw's own).

        Returns:
            ``{(draw, stepping logs, confounded, servo fit): identify_real's result}``.
        """
        from sysid.identified import load_identified  # lazy: loads the engines

        want = sorted({(self._stepping(s), s.identified_confounded, s.servo_fit) for s in self.specs
                       if s.servo in STAGED_SERVO})
        out = {}
        for d in range(self.cfg.data_seeds):
            for stepping, conf, which in want:
                terms, _ = load_identified([servofits[d, stepping, conf, which]])
                t0 = time.perf_counter()
                with self._phase("diagnoses"):
                    out[d, stepping, conf, which] = r = self._identify(
                        d, stepping, terms, "_servo" + ("" if which == "air" else "refit"))
                self._say(f"identified draw {d} again on the in-air servo fit ({which}): ground Sq "
                          f"{1000 * r['terrain_rms_height']:.2f} mm ({time.perf_counter() - t0:.0f} s)")
        return out

    def _mean_physics(self, spec: WorldSpec | None = None) -> str:
        """The report of the real world's mean physics for the identified sim (``oracle:mean=1:
        engine=mujoco``; :func:`experiments.runtime.tasks.mean_physics_report`), written once into the run;
        with ``spec``'s ``compliance=``, ``backlash=0`` and ``drop=`` in a folder of its own."""
        from experiments.runtime.tasks import mean_physics_report  # lazy: loads the engines

        compliance = spec.oracle_compliance if spec is not None and spec.oracle_compliance else None
        backlash = spec is None or spec.oracle_backlash
        drop = spec.oracle_drop.split("+") if spec is not None and spec.oracle_drop else []
        form = (f"_compliance{compliance:g}" if compliance else "") + ("" if backlash else "_nobacklash") \
            + (f"_drop{'+'.join(drop)}" if drop else "")
        path = os.path.join(self.run_dir, "oracle", f"mean_physics_{self.cfg.profile}{form}", "report.json")
        if not os.path.exists(path):
            os.makedirs(os.path.dirname(path), exist_ok=True)
            rep = mean_physics_report(self.cfg.profile, self.cfg.robot, ground_compliance=compliance,
                                      drop=drop + ([] if backlash else ["backlash"]))
            atomic_write_text(path, json.dumps(rep, indent=1))
        return path

    def _mean_ground_level(self, ground: str) -> float:
        """The level of the real world's mean ground as ``ground`` ([m]): for ``"real"`` the lumpy
        terrain's mean amplitude (:func:`experiments.runtime.tasks.mean_profile`), for ``"model"`` the RMS
        height the mean-physics report gives the identified sim's surface (:meth:`_mean_physics`)."""
        from envs.effects import get_profile  # lazy: loads the engines
        from experiments.runtime.tasks import mean_profile  # lazy: loads the engines

        if ground == "real":
            return float(mean_profile(get_profile(self.cfg.profile, get_robot(self.cfg.robot))).terrain_amplitude[0])
        with open(self._mean_physics()) as f:
            effects = json.load(f)["effects"]
        return float(effects[0]["value"]) if effects else 0.0

    def _model_dir(self, spec: WorldSpec, draw: int) -> str:
        return os.path.join(self.run_dir, "models", f"{spec.key}_d{draw}")

    def prepare(self) -> dict:
        """Grounding walks, identifications and fitted transformers for every world and draw.

        Returns:
            ``{world name: {draw: {"transformer": dir or None, "identified": [reports] or None,
            "real_walks", "real_seconds", "excitation_logs", "excitation_seconds", ...}}}``.
        """
        cfg = self.cfg
        out: dict = {s.name: {} for s in self.specs}
        counts = sorted({self._stepping(s) for s in self.specs if s.needs_identification})
        idents: dict[tuple[int, int], dict] = {}
        self._calibration = None
        if counts:
            t0 = time.perf_counter()
            # one constant of the testbed, whatever the run's seed (seed 0's runs always had it); the
            # package ships it for the pinned engines, so a run copies it
            self._calibration = calibrate_engines(os.path.join(self.run_dir, "identified", "calibration"),
                                                  seed=ENGINE_GAP_SEED, floating=max(counts) > 0)
            self._say(f"engine-gap calibration ready ({time.perf_counter() - t0:.0f} s)")
            self._record_excitation(counts)
            t0 = time.perf_counter()
            for d in range(cfg.data_seeds):  # the diagnosis runs its replays on every core itself
                for n in counts:
                    with self._phase("diagnoses"):
                        idents[d, n] = r = self._identify(d, n)
                    self._say(f"identified draw {d} ({n} stepping logs): {len(r['effects'])} terms, ground Sq "
                              f"{1000 * r['terrain_rms_height']:.2f} mm, {r['logs']} logs ({r['wall_s']:.0f} s)"
                              + "".join(f"; WARNING: the {k} diagnosis ran out of time (raise --identify-budget)"
                                        for k in r.get("time_budget_reached", [])))
            self._say(f"identification done ({time.perf_counter() - t0:.0f} s)")
        walkfits = self._walk_fits(idents)
        servofits = self._servo_fits(idents)
        staged = self._staged(servofits)
        fits = []
        for d in range(cfg.data_seeds):
            for s in self.specs:
                info: dict = {"transformer": None, "identified": None, "real_walks": 0, "real_seconds": 0.0,
                              "excitation_logs": 0, "excitation_seconds": 0.0}
                if s.needs_identification:
                    idn = staged[d, self._stepping(s), s.identified_confounded, s.servo_fit] \
                        if s.servo in STAGED_SERVO else idents[d, self._stepping(s)]
                    effects, reports = idn["effects"], list(idn["reports"])
                    if s.servo:  # the common servo stiffness fitted to the in-air or stepping logs; a staged
                        # world's stepping diagnosis was made on top of it, so its report comes after
                        fit = servofits[d, self._stepping(s), s.identified_confounded, s.servo_fit]
                        reports.insert(1 if s.servo in STAGED_SERVO else len(reports), fit)
                        with open(fit) as f:  # its held-out costs (and what a refit moved)
                            info["servo_fit"] = json.load(f).get("servo_fit")
                    if s.walkfit:  # the terms fitted to the real walks override the diagnosis's
                        wf = walkfits[d, self._stepping(s), s.identified_confounded, s.real_walks, s.walkfit]
                        reports.append(wf["path"])
                        info["real_paths"] = wf["real_paths"]
                    if not s.identified_confounded or s.walkfit or s.servo:  # the terms this world builds in
                        from sysid.identified import load_identified  # lazy: loads the engines

                        terms, rms = load_identified(reports, s.identified_confounded)
                        effects = {t.label(): v for t, v in sorted(terms.items())}
                    info.update(identified=reports, excitation_logs=idn["logs"],
                                excitation_seconds=idn["seconds"], effects=effects,
                                terrain_rms_height=rms if s.walkfit else idn["terrain_rms_height"])
                if s.grounded:
                    thetas = self._data_gaits(s.data_gaits, d)
                    g = "" if s.data_gaits == 1 else f"_g{s.data_gaits}"
                    real = self._walks("real", _seeds(cfg.seed, _GROUND_REAL, d, n=s.real_walks), f"real_d{d}{g}", thetas)
                    sim_kw = {"action_noise": s.exploration_noise}
                    if s.kind == "hybrid":
                        sim_kw.update(identified=info["identified"], identified_confounded=s.identified_confounded)
                    base = "ident" if s.kind == "hybrid" else "sim"
                    if s.kind == "hybrid" and self._stepping(s) != cfg.identify_floating_logs:
                        base += f"{self._stepping(s)}"  # walks on another identified world
                    if s.kind == "hybrid" and not s.identified_confounded:
                        base += "x"  # ... or on one without the contact terms confounded with the ground
                    if s.kind == "hybrid" and s.walkfit:
                        base += f"w{s.walkfit}"  # ... or on one with terms fitted to the real walks
                    if s.kind == "hybrid" and s.servo:
                        base += {"stepping": "s", "air": "a", "staged": "g", "refit": "r"}[s.servo]  # ... or with the servo stiffness fitted
                    sim = self._walks("identified" if s.kind == "hybrid" else "sim",
                                      _seeds(cfg.seed, _GROUND_SIM, d, n=s.sim_walks),
                                      f"{base}_d{d}_n{s.exploration_noise:g}{g}", thetas, **sim_kw)
                    mdir = self._model_dir(s, d)
                    gcfg = s.grounding.to_dict()
                    if s.delay_auto:
                        gcfg["delay"] = identified_delay(info["identified"])
                    info["delay"] = int(gcfg.get("delay", 0))
                    fits.append({"real": real, "sim": sim, "out": mdir, "config": gcfg,
                                 "state": s.state, "history": s.history,
                                 **({"identified": info["identified"], "identified_confounded": s.identified_confounded}
                                    if s.kind == "hybrid" else {}),
                                 "seed": _seeds(cfg.seed, _FIT, d, n=1)[0] % 1_000_000, "world": s.name, "draw": d,
                                 **cfg.task_robot()})
                    info["transformer"] = mdir
                    info["real_paths"], info["data_gait"] = real, thetas[0]
                out[s.name][d] = info
        self._record_walks()
        for info in (i for per in out.values() for i in per.values() if i.get("real_paths")):
            walks = [_rec_summary(p) for p in info["real_paths"]]
            info["real_walks"] = len(walks)
            info["real_seconds"] = float(sum(w[0] for w in walks))
            info["real_walk_falls"] = int(sum(w[1] for w in walks))
        todo = [f for f in fits if not os.path.exists(os.path.join(f["out"], "transformer.json"))]
        if todo:
            t0 = time.perf_counter()
            self._say(f"fitting {len(todo)} transformers ({len(fits) - len(todo)} resumed)")
            with self._phase("fits"):
                fitted = self.ex.map(fit_grounding_task, todo)
            for f, r in zip(todo, fitted):
                self._say(f"  {f['world']} draw {f['draw']}: forward val {r['forward_val']:.3f}, inverse val "
                          f"{r['inverse_val']:.3f} ({r['n_real']} real / {r['n_sim']} sim transitions, {r['wall_s']:.0f} s)")
            self._say(f"fits done ({time.perf_counter() - t0:.0f} s)")
        return out

    # ---------------------------------------------------------------- episodes
    def _world_tasks(self, spec: WorldSpec, draw: int, info: dict, gaits: list[dict]) -> list[dict]:
        cfg = self.cfg
        n = 1 if spec.deterministic else cfg.episodes
        seeds = _seeds(cfg.seed, _WORLD, n=n)  # the same episode seeds for every world, draw and gait
        base = {"seconds": cfg.seconds, "profile": cfg.profile, **cfg.task_robot()}
        if spec.kind == "oracle":  # real episodes on seeds of their own, new for every draw
            base["world"] = "real"
            seeds = _seeds(cfg.seed, _ORACLE, draw, n=n)
            if spec.oracle_mean:  # its mean physics, one point (experiments.runtime.tasks.mean_profile)
                base["profile"] = f"{cfg.profile}:mean"
            if spec.oracle_engine == "mujoco":  # ... built into the sim (experiments.runtime.tasks.mean_physics_report)
                del base["profile"]
                base.update(world="identified", identified=[self._mean_physics(spec)])
            if spec.oracle_ground and spec.oracle_ground != OWN_GROUND[spec.oracle_engine]:
                # ... on the other engine's ground: the very surface that engine walks for the seed
                base["ground"] = [spec.oracle_ground, self._mean_ground_level(spec.oracle_ground)]
        elif spec.kind in ("sim", "ane"):
            base["world"] = "sim"
            if spec.kind == "ane":
                base["action_noise"] = spec.sigma
        elif spec.kind == "identified":
            base.update(world="identified", identified=info["identified"], identified_terms=spec.identified_terms,
                        identified_ground=spec.identified_ground, identified_confounded=spec.identified_confounded)
        else:
            base.update(world="grounded", transformer=info["transformer"])
            if spec.kind == "hybrid":
                base.update(identified=info["identified"], identified_confounded=spec.identified_confounded)
        if spec.envelope:  # the noise envelope on top (sgatwalk optimize --methods sgat+ane)
            base["action_noise"] = spec.envelope
        return [{**base, "theta": g["theta"], "seed": s, "key": f"w|{spec.key}|d{draw}|{g['name']}|e{e}"}
                for g in gaits for e, s in enumerate(seeds)]

    def run(self) -> dict:
        """Measure everything not measured yet and return (and save) the result."""
        cfg = self.cfg
        self._check_config()
        clock = WallClock(self.run_dir, legacy=os.path.join(self.run_dir, "fidelity.json"))
        gaits = self.panel()
        self._say(f"panel: {len(gaits)} gaits; {cfg.real_trials} real trials each; worlds "
                  f"{', '.join(s.name for s in self.specs)}; {cfg.data_seeds} draws of the real data")
        real_seeds = _seeds(cfg.seed, _REAL, n=cfg.real_trials)
        with self._phase("real trials"):
            self._run([{"world": "real", "theta": g["theta"], "seed": s, "seconds": cfg.seconds, "profile": cfg.profile,
                        "key": f"real|{g['name']}|t{j}", **cfg.task_robot()} for g in gaits for j, s in enumerate(real_seeds)],
                      "real trials")
        prep = self.prepare()
        tasks = []
        for spec in self.specs:
            for d in (range(cfg.data_seeds) if spec.per_draw else [0]):
                tasks += self._world_tasks(spec, d, prep[spec.name][d], gaits)
        with self._phase("world episodes"):
            self._run(tasks, "training-world episodes")
        self.replay(prep)
        res = self.result(gaits, prep)
        res["wall_s"] = clock.save()
        res["phases_s"] = self.phases()
        self.write(res)
        return res

    def replay(self, prep: dict) -> None:
        """Teacher-force every grounded world of the data gait alone along its draw's real grounding
        walks (``experiments.runtime.tasks.replay_walk_task``: the real next states in place of the forward
        model); the results go to ``replay.json`` in the draw's model directory (resumable) and into
        ``prep`` as ``info["replay"]``."""
        from experiments.runtime.tasks import replay_walk_task  # lazy: loads the engines

        todo, first = [], {}
        for s in self.specs:
            if not s.grounded or s.data_gaits != 1:
                continue
            for d in range(self.cfg.data_seeds):
                info = prep[s.name][d]
                path = os.path.join(info["transformer"], "replay.json")
                if os.path.exists(path):
                    with open(path) as f:
                        info["replay"] = json.load(f)
                    continue
                hybrid = s.kind == "hybrid"
                tasks = [{"recording": p, "transformer": info["transformer"], "theta": info["data_gait"],
                          "seconds": self.cfg.seconds, **self.cfg.task_robot(),
                          **({"identified": info["identified"], "identified_confounded": s.identified_confounded}
                             if hybrid else {})} for p in info["real_paths"]]
                # worlds that differ only in their forward model (gat, sgat, sgat:shadow=...) replay alike
                sig = (_inverse_signature(info["transformer"]), tuple(info["real_paths"]),
                       tuple(info["identified"] or ()) if hybrid else (), s.identified_confounded if hybrid else True)
                todo.append((info, path, tasks if sig not in first else None, sig))
                first.setdefault(sig, len(todo) - 1)
        if not todo:
            return
        t0 = time.perf_counter()
        flat = [t for _, _, tasks, _ in todo if tasks for t in tasks]
        self._say(f"teacher-forcing {len(flat)} grounding walks ({len(first)} sets of inverse models)")
        with self._phase("teacher forcing"):
            results = iter(self.ex.map(replay_walk_task, flat))
        for info, path, tasks, sig in todo:
            info["replay"] = [next(results) for _ in tasks] if tasks else todo[first[sig]][0]["replay"]
            atomic_write_text(path, json.dumps(jsonable(info["replay"]), indent=1))
        self._say(f"  teacher-forced ({time.perf_counter() - t0:.0f} s)")

    # ---------------------------------------------------------------- results
    def _matrix(self, prefix: str, gaits, n: int, what: str) -> np.ndarray:
        return np.array([[float(self._episodes[f"{prefix}|{g['name']}|{'t' if prefix == 'real' else 'e'}{j}"][what])
                          for j in range(n)] for g in gaits])

    def result(self, gaits, prep) -> dict:
        cfg = self.cfg
        R = self._matrix("real", gaits, cfg.real_trials, "fitness")
        F = self._matrix("real", gaits, cfg.real_trials, "fell")
        real_fit, real_fall = R.mean(1), F.mean(1)
        rel = split_half_reliability(R, seed=cfg.seed)
        base_rate = float(F.mean())
        out = {"config": cfg.to_dict(), "gaits": [g["name"] for g in gaits],
               "real": {"fitness": real_fit.tolist(), "fitness_se": (R.std(1, ddof=1) / math.sqrt(R.shape[1])).tolist(),
                        "fall_rate": real_fall.tolist(), "speed_cm_s": self._matrix("real", gaits, cfg.real_trials,
                                                                                    "speed_cm_s").mean(1).tolist(),
                        "trials": cfg.real_trials, "fitness_trials": R.tolist(), **rel,
                        "brier_base_rate": brier_score(np.full(len(gaits), base_rate), F),
                        "brier_own_frequency": brier_score(real_fall, F)},
               "worlds": {}}
        for spec in self.specs:
            draws, curve = [], {}
            n = 1 if spec.deterministic else cfg.episodes
            for d in (range(cfg.data_seeds) if spec.per_draw else [0]):
                pre = f"w|{spec.key}|d{d}"
                W = self._matrix(pre, gaits, n, "fitness")
                WF = self._matrix(pre, gaits, n, "fell")
                wf, wp = W.mean(1), WF.mean(1)
                info = prep[spec.name][d]
                # the world's own episode noise: how well its n-episode means would rank against themselves
                # (a deterministic world and single episodes have none to measure)
                own = split_half_reliability(W, seed=cfg.seed + d) if n >= 2 else None
                for k in episode_counts(n):  # the same figures from the first k episodes of every gait
                    curve.setdefault(k, []).append(
                        {"draw": d, **_draw_metrics(W[:, :k].mean(1), WF[:, :k].mean(1), real_fit, F)})
                draws.append({
                    "draw": d, "fitness": wf.tolist(), "fall_rate": wp.tolist(), "fitness_episodes": W.tolist(),
                    **_draw_metrics(wf, wp, real_fit, F),
                    "rho_ci90": list(bootstrap_spearman(wf, R, n_boot=cfg.bootstrap, seed=cfg.seed + d)),
                    "world_reliability": None if own is None else own["reliability"],
                    "world_ceiling": None if own is None else own["ceiling"],
                    "real_walks": info["real_walks"], "real_seconds": info["real_seconds"],
                    "real_walk_falls": info.get("real_walk_falls", 0),
                    **({"replay": _replay_summary(info["replay"])} if info.get("replay") else {}),
                    "excitation_logs": info["excitation_logs"], "excitation_seconds": info["excitation_seconds"],
                    **({"effects": info.get("effects"), "terrain_rms_height": info.get("terrain_rms_height")}
                       if spec.needs_identification else {}),
                    **({"servo_fit": info["servo_fit"]} if info.get("servo_fit") else {}),
                    **({"delay": info["delay"]} if info.get("delay") else {}),
                })
            out["worlds"][spec.name] = {"kind": spec.kind, "episodes": n, "draws": draws, "summary": _summary(draws),
                                        "data_gaits": spec.data_gaits if spec.grounded else None,
                                        "grounding": spec.grounding.to_dict() if spec.grounding else None,
                                        **({"identified_confounded": spec.identified_confounded}
                                           if spec.needs_identification else {}),
                                        **({"oracle_mean": True} if spec.oracle_mean else {}),
                                        **({"oracle_engine": spec.oracle_engine} if spec.oracle_engine != "pybullet" else {}),
                                        **({"oracle_ground": spec.oracle_ground} if spec.oracle_ground else {}),
                                        **({"oracle_compliance": spec.oracle_compliance} if spec.oracle_compliance else {}),
                                        **({"oracle_backlash": False} if not spec.oracle_backlash else {}),
                                        **({"oracle_drop": spec.oracle_drop.split("+")} if spec.oracle_drop else {}),
                                        **({"by_episodes": {str(k): {"draws": c, "summary": _summary(c)}
                                                            for k, c in curve.items()}} if curve else {})}
        out["paired"] = paired_rows(out, n_boot=cfg.bootstrap, seed=cfg.seed)
        if cfg.params:  # each world on the drawn and the given gaits apart
            out["groups"] = group_rows(out)
        return out

    def write(self, res: dict) -> None:
        atomic_write_text(os.path.join(self.run_dir, "fidelity.json"), json.dumps(jsonable(res), indent=1))
        atomic_write_text(os.path.join(self.run_dir, "table.txt"), format_table(res) + "\n")
        plot(res, os.path.join(self.run_dir, "fidelity.png"))
        if len({r["episodes"] for r in episodes_rows(res)}) > 1:
            plot_episodes(res, os.path.join(self.run_dir, "fidelity_episodes.png"))


def format_phases(phases: dict[str, float], min_s: float = 0.0) -> str:
    """``"real trials 138 s, diagnoses 375 s, ..."``: the phases of ``phases_s`` [s] that took at least
    ``min_s``, in run order (the text output's ``time:`` line and the README's)."""
    return ", ".join(f"{k} {v:.0f} s" for k, v in phases.items() if v >= min_s)


def _rec_summary(path: str) -> tuple[float, bool]:
    """A recording's length [s] and whether the robot fell in it (``meta["fell"]``)."""
    from envs import Recording  # lazy: loads the engines

    rec = Recording.from_parquet(path)
    return float(len(rec) * rec.meta["control_dt"]), bool(rec.meta.get("fell", False))


def _inverse_signature(model_dir: str) -> str:
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


def _replay_summary(rows: list[dict]) -> dict:
    """Teacher-forced replays of one draw's grounding walks: counts of falls (``fell_with_real``: the
    sim fell on a walk that fell for real; ``fell_without_real``: on one that did not) and the median
    RMS error of the leg joint angles against the real walks [rad], forced and ungrounded."""
    real = np.array([r["real_fell"] for r in rows], dtype=bool)
    sim = np.array([r["fell"] for r in rows], dtype=bool)
    return {"walks": len(rows), "real_fell": int(real.sum()), "fell": int(sim.sum()),
            "fell_with_real": int((sim & real).sum()), "fell_without_real": int((sim & ~real).sum()),
            "q_rms_rad": float(np.median([r["q_rms_rad"] for r in rows])),
            "q_rms_plain_rad": float(np.median([r["q_rms_plain_rad"] for r in rows]))}


def replay_totals(replays: list[dict]) -> dict:
    """A world's teacher-forced replays (one :func:`_replay_summary` per draw) over all its draws:
    walks, real falls, the sim's falls on walks that fell and on those that did not (sums), and the
    median over the draws of the leg-joint RMS errors [rad], forced and ungrounded."""
    return {k: sum(r[k] for r in replays) for k in ("walks", "real_fell", "fell_with_real", "fell_without_real")} | {
        k: float(np.median([r[k] for r in replays])) for k in ("q_rms_rad", "q_rms_plain_rad")}


def episode_counts(n: int) -> list[int]:
    """The episode counts per gait a world of ``n`` episodes is also scored at (``by_episodes`` of a
    fidelity result): 1, 2, 4, ... below ``n``, and ``n``; none for a single episode."""
    return [] if n < 2 else sorted({2 ** i for i in range(n.bit_length()) if 2 ** i < n} | {n})


def _draw_metrics(wf: np.ndarray, wp: np.ndarray, real_fit: np.ndarray, real_falls: np.ndarray) -> dict:
    """One draw of a world against the real trials: Spearman ρ, MAE and bias (world − real) of the
    fitness, the Brier score of its fall frequencies ``wp`` (G,) against the real falls (G, M), and
    the regret of its pick (``experiments.runtime.stats``)."""
    return {"rho": spearman(wf, real_fit), "mae": float(np.mean(np.abs(wf - real_fit))),
            "bias": float(np.mean(wf - real_fit)), "brier": brier_score(wp, real_falls),
            "pick_regret": pick_regret(wf, real_fit)}


def episodes_view(res: dict, k: int) -> dict:
    """A fidelity result as it would read with ``k`` episodes per gait in every stochastic world: each
    world that has ``by_episodes[k]`` gets those draws and summary (the first k of its episodes, on the
    same seeds as a run with ``--episodes k``); deterministic worlds keep theirs; worlds measured with
    fewer than ``k`` episodes are left out. The targets (:func:`fidelity_targets`) read it like a result.

    Raises:
        ValueError: ``k`` < 1.
    """
    if k < 1:
        raise ValueError(f"episodes per gait must be >= 1, got {k}")
    worlds = {}
    for name, w in res["worlds"].items():
        cur = (w.get("by_episodes") or {}).get(str(k))
        if cur is not None:
            worlds[name] = {**w, "episodes": k, "draws": cur["draws"], "summary": cur["summary"]}
        elif w.get("kind", name.split(":")[0]) in DETERMINISTIC_KINDS:  # one episode is its answer, whatever k
            worlds[name] = w
        elif k == w.get("episodes"):  # a world measured with k episodes, in a run saved before by_episodes
            worlds[name] = w
    return {**res, "worlds": worlds}


def _over_draws(values) -> dict:
    """``{"median", "min", "max", "spread"}`` of one figure over the draws, its non-finite values left
    out (all NaN where none is finite)."""
    v = np.asarray(values, dtype=float)
    ok = v[np.isfinite(v)]
    if not len(ok):
        return {"median": math.nan, "min": math.nan, "max": math.nan, "spread": math.nan}
    return {"median": float(np.median(ok)), "min": float(ok.min()), "max": float(ok.max()),
            "spread": float(ok.max() - ok.min())}


def _range_text(s: dict | None, fmt: str = "{:.2f}") -> str:
    """A figure over the draws as text: 'median [min, max]' ('-' for None)."""
    return "-" if s is None else f"{fmt.format(s['median'])} [{fmt.format(s['min'])}, {fmt.format(s['max'])}]"


def _summary(draws: list[dict]) -> dict:
    def agg(key):
        return _over_draws([d[key] for d in draws])
    s = {k: agg(k) for k in ("rho", "mae", "bias", "brier")}
    if all("pick_regret" in d for d in draws):  # runs saved before it have none
        s["pick_regret"] = agg("pick_regret")
    if all(d.get("world_ceiling") is not None for d in draws):  # stochastic worlds of runs that measured it
        s["world_ceiling"] = agg("world_ceiling")
    s["abs_bias_median"] = float(np.median(np.abs([d["bias"] for d in draws])))
    s["draws"] = len(draws)
    return s


def first_world(res: dict, kind: str) -> str | None:
    """The first world of ``kind`` that a fidelity result lists (its reference world of that kind:
    the others are variants), or None."""
    return next((n for n, w in res["worlds"].items() if w.get("kind", n.split(":")[0]) == kind), None)


def ranking_target(ceiling: float) -> float:
    """The grounding issue's target for a world's worst ρ over the draws: 0.8, or within 0.1 of the
    ceiling the real trials' noise allows where that caps ρ lower (``min(0.8, ceiling - 0.1)``)."""
    return min(0.8, ceiling - 0.1)


def fidelity_targets(res: dict, world: str = "sgat") -> list[tuple[str, bool, str]]:
    """The targets of the grounding issue for a grounded world (default SGAT) on a fidelity result:
    worst ρ over the draws ≥ 0.8 or within 0.1 of the real trials' ceiling, median |bias| ≤ 2, bias
    spread ≤ 4, Brier below the plain sim's and below GAT's on every draw, ρ ≥ GAT's on every draw.

    Returns:
        ``[(target, met, measured)]``, compared with the plain sim and the first GAT world listed
        (:func:`first_world`; a target whose reference world the run lacks is left out); empty if
        ``world`` is not in the result.
    """
    if world not in res["worlds"]:
        return []
    w = res["worlds"][world]
    draws = w["draws"]
    ceiling = res["real"]["ceiling"]
    worst = min(d["rho"] for d in draws)
    out = [("worst ρ over the draws ≥ 0.8, or within 0.1 of the ceiling", worst >= ranking_target(ceiling),
            f"{worst:.2f} (ceiling {ceiling:.2f})"),
           ("median |bias| ≤ 2 fitness points", w["summary"]["abs_bias_median"] <= 2,
            f"{w['summary']['abs_bias_median']:.1f}"),
           ("bias spread over the draws ≤ 4", w["summary"]["bias"]["spread"] <= 4, f"{w['summary']['bias']['spread']:.1f}")]
    gat = first_world(res, "gat")
    for label, other in (("SIM", "sim" if "sim" in res["worlds"] else None), ("GAT", gat)):
        if other:
            ob = res["worlds"][other]["draws"]
            ref = [ob[min(i, len(ob) - 1)]["brier"] for i in range(len(draws))]
            ok = all(d["brier"] < r for d, r in zip(draws, ref))
            out.append((f"Brier below {label}'s on every draw", ok,
                        ", ".join(f"{d['brier']:.3f} vs {r:.3f}" for d, r in zip(draws, ref))))
    if gat:
        g = res["worlds"][gat]["draws"]
        ok = all(d["rho"] >= e["rho"] for d, e in zip(draws, g))
        out.append(("ρ ≥ GAT's on every draw", ok, ", ".join(f"{d['rho']:.2f} vs {e['rho']:.2f}" for d, e in zip(draws, g))))
    return out


def world_pairs(names: list[str], kinds: dict[str, str]) -> list[tuple[str, str]]:
    """The pairs (world, reference) that :func:`paired_rows` compares, in the worlds' order: every
    world against the plain ``sim`` (does it rank better than the sim it starts from?), a variant
    with options against its plain kind (``hybrid:gate=0.9`` against ``hybrid``), the issue's
    comparisons ``sgat`` − ``gat``, ``hybrid`` − ``identified``, ``hybrid`` − ``sgat``, where the run
    has both, and any two worlds of one kind one setting apart, the later against the earlier
    (``hybrid:alpha=0.3:delay=auto`` against ``hybrid:alpha=0.3``; the four mean-physics oracles of
    engine × ground, edge by edge; a ``drop=`` ablation against the world it ablates, not against an
    ablation of other families); and a MuJoCo form of the mean physics rebuilt with ``compliance=``,
    ``backlash=0`` or ``drop=`` against ``oracle:mean=1``, the PyBullet form it stands for. Where the
    run has ``oracle`` (the real world itself on fresh seeds, as many episodes per gait), every world
    that learns from real data or adds noise (``ane``, ``gat``, ``sgat``, ``identified``, ``hybrid``
    and their variants) against it: does the world rank the gaits measurably worse than the real
    world would as a training world?"""
    pairs = []
    for n in names:
        if n != "sim" and "sim" in names:
            pairs.append((n, "sim"))
        base = kinds.get(n, n.split(":")[0])
        if ":" in n and base in names and base != "sim":
            pairs.append((n, base))
    pairs += [p for p in (("sgat", "gat"), ("hybrid", "identified"), ("hybrid", "sgat")) if p[0] in names and p[1] in names]
    specs = {}
    for n in names:
        try:
            specs[n] = parse_world(n)
        except ValueError:  # a name of an earlier round's options: compared by the rules above only
            continue
    pairs += [(a, b) for i, a in enumerate(names) for b in names[:i]
              if a in specs and b in specs and _settings_apart(specs[a], specs[b]) == 1
              and _nested_drops(specs[a], specs[b])]
    if "oracle:mean=1" in names:  # a rebuilt MuJoCo form against the PyBullet mean physics it stands for
        pairs += [(n, "oracle:mean=1") for n, s in specs.items()
                  if s.kind == "oracle" and s.oracle_engine == "mujoco"
                  and (s.oracle_compliance or not s.oracle_backlash or s.oracle_drop)]
    if "oracle" in names:  # every learned world against the real world itself
        pairs += [(n, "oracle") for n in names if kinds.get(n, n.split(":")[0]) in _LEARNED_KINDS]
    return list(dict.fromkeys(pairs))


def _nested_drops(a: WorldSpec, b: WorldSpec) -> bool:
    """Whether one world's ``drop=`` families hold the other's: an ablation is compared with the world
    it ablates, not with an ablation of other families."""
    fa, fb = (set(filter(None, s.oracle_drop.split("+"))) for s in (a, b))
    return fa <= fb or fb <= fa


def _settings_apart(a: WorldSpec, b: WorldSpec) -> int:
    """How many settings two worlds of one kind differ in (the grounding's counted one by one); a large
    number for worlds of different kinds."""
    if a.kind != b.kind:
        return 1 << 30
    da, db = dataclasses.asdict(a), dataclasses.asdict(b)
    ga, gb = da.pop("grounding") or {}, db.pop("grounding") or {}
    return sum(da[k] != db[k] for k in da if k != "name") + sum(ga.get(k) != gb.get(k) for k in set(ga) | set(gb))


def paired_rows(res: dict, *, n_boot: int = 1000, seed: int = 0) -> list[dict]:
    """Paired comparisons of the worlds' rankings (:func:`world_pairs`): per pair, the mean over the
    draws of ρ_world − ρ_reference with a 90 % interval and a two-sided p-value from a bootstrap over
    the gaits, the real trials and the episodes (:func:`experiments.runtime.stats.paired_spearman_difference`).
    The worlds' draws are paired: draw d of every world learns from the same real data. Empty for a
    result saved without per-episode fitness (before the twenty-third round). The bootstrap's
    replicates rank worse than the observed worlds, a stochastic world's more than a deterministic
    one's: the test is conservative for a claim that a stochastic world ranks better than the plain
    sim, not for one that it ranks worse (``paired_spearman_difference``'s caveat).

    ``ci_panel`` and ``p_value_panel``: the same with the panel's gaits kept (the trials and episodes
    resampled only): is the difference beyond the noise on this panel? ``ci`` and ``p_value`` also
    resample the gaits: would it hold on another panel of as many gaits from the same region?

    Returns:
        ``[{"world", "reference", "diff", "per_draw", "ci", "p_value", "n_boot", "ci_panel",
        "p_value_panel"}]``.
    """
    trials = res["real"].get("fitness_trials")
    worlds = res["worlds"]
    if trials is None or not all("fitness_episodes" in d for w in worlds.values() for d in w["draws"]):
        return []
    eps = {n: np.array([d["fitness_episodes"] for d in w["draws"]]) for n, w in worlds.items()}
    return [{"world": a, "reference": b, **paired_test(eps[a], eps[b], trials, n_boot=n_boot, seed=seed)}
            for a, b in world_pairs(list(worlds), {n: w.get("kind", n.split(":")[0]) for n, w in worlds.items()})]


def paired_test(world_a, world_b, trials, *, n_boot: int = 1000, seed: int = 0) -> dict:
    """:func:`experiments.runtime.stats.paired_spearman_difference` of two worlds' per-episode fitness
    ((D, G, E) each) on the real trials ``trials`` (G, M), for a new panel (``ci``, ``p_value``: the
    gaits resampled too) and for this panel (``ci_panel``, ``p_value_panel``: the gaits kept).

    Returns:
        ``{"diff", "per_draw", "ci", "p_value", "n_boot", "ci_panel", "p_value_panel"}``.
    """
    panel = paired_spearman_difference(world_a, world_b, trials, n_boot=n_boot, seed=seed, resample_gaits=False)
    return {**paired_spearman_difference(world_a, world_b, trials, n_boot=n_boot, seed=seed),
            "ci_panel": panel["ci"], "p_value_panel": panel["p_value"]}


def format_paired(res: dict) -> list[str]:
    """The text lines of ``res["paired"]`` (none when the result has none)."""
    rows = res.get("paired") or []
    if not rows:
        return []

    lines = ["", "paired differences of rho (world - reference, the mean over the draws; 90% bootstrap intervals and "
             "two-sided p over the real trials and episodes on this panel, and over the gaits too, for a new panel):",
             f"  {'world - reference':40s} {'diff':>5s} {'this panel':>16s} {'p':>6s} {'a new panel':>16s} {'p':>6s}"]
    for r in rows:
        lines.append(f"  {r['world'] + ' - ' + r['reference']:40s} {r['diff']:+5.2f} {format_ci(r['ci_panel']):>16s} "
                     f"{p_text(r['p_value_panel'], r['n_boot']):>6s} {format_ci(r['ci']):>16s} {p_text(r['p_value'], r['n_boot']):>6s}")
    return lines


def format_ci(ci) -> str:
    """A difference's interval as text, ``"[-0.12, +0.30]"``, or ``"-"`` where it is undefined."""
    return "-" if ci[0] is None or not math.isfinite(ci[0]) else f"[{ci[0]:+.2f}, {ci[1]:+.2f}]"


def p_text(p: float, n_boot: int) -> str:
    """A bootstrap p-value as text: ``"0.042"``, or ``"<0.001"`` for 0 (every one of ``n_boot``
    replicates on one side: p < 1/n_boot)."""
    if p is None or not math.isfinite(p):
        return "-"
    return f"<{1 / max(n_boot, 1):.2g}" if p == 0 else f"{p:.3f}"


def format_table(res: dict) -> str:
    """The fidelity table: one row per world, figures as median [min, max] over the draws."""
    r = res["real"]
    lines = [f"{len(res['gaits'])} gaits x {r['trials']} paired real trials; real fitness "
             f"{min(r['fitness']):.1f} .. {max(r['fitness']):.1f}, falls {100 * float(np.mean(r['fall_rate'])):.0f} %",
             f"ceiling of rho from the real trials' noise: {r['ceiling']:.2f} (split-half reliability "
             f"{r['reliability']:.2f}); Brier of the constant base rate {r['brier_base_rate']:.3f}, of each gait's own "
             f"real frequency {r['brier_own_frequency']:.3f}",
             "",
             f"{'world':28s} {'draws':>5s} {'Spearman rho':>22s} {'worst 90% CI':>14s} {'MAE':>14s} "
             f"{'bias (world-real)':>24s} {'Brier':>22s} {'pick regret':>20s} {'own-noise ceiling':>18s}",
             "-" * 176]

    rng3 = _range_text

    for name, w in res["worlds"].items():
        s = w["summary"]
        worst = min(w["draws"], key=lambda d: -np.inf if d["rho"] is None or not math.isfinite(d["rho"]) else d["rho"])
        ci = worst["rho_ci90"]
        ci_txt = "-" if ci[0] is None or not math.isfinite(ci[0]) else f"[{ci[0]:.2f}, {ci[1]:.2f}]"
        lines.append(f"{name:28s} {s['draws']:>5d} {rng3(s['rho']):>22s} {ci_txt:>14s} {s['mae']['median']:>14.1f} "
                     f"{s['bias']['median']:>+8.1f} (spread {s['bias']['spread']:4.1f}) {rng3(s['brier'], '{:.3f}'):>22s} "
                     f"{rng3(s['pick_regret'], '{:.1f}') if 'pick_regret' in s else '-':>20s} "
                     f"{_own(s):>18s}")
    forced = [(n, [d["replay"] for d in w["draws"]]) for n, w in res["worlds"].items()
              if w["draws"] and all("replay" in d for d in w["draws"])]
    if forced:
        lines += ["", "teacher-forced along each draw's grounding walks (their real next states in place of the forward "
                  "model; summed over the draws):"]
        for name, rp in forced:
            t = replay_totals(rp)
            lines.append(f"  {name:26s} sim fell on {t['fell_with_real']}/{t['real_fell']} walks that fell, "
                         f"{t['fell_without_real']}/{t['walks'] - t['real_fell']} that did not; leg joints "
                         f"{t['q_rms_rad']:.3f} rad RMS from the real walk (ungrounded {t['q_rms_plain_rad']:.3f})")
    lines += format_paired(res)
    lines += format_groups(res)
    lines += format_episodes(res)
    return "\n".join(lines)


def episodes_rows(res: dict) -> list[dict]:
    """Fidelity against the number of episodes per gait, one row per stochastic world and count k of
    ``by_episodes`` (1, 2, 4, ... and the run's own): worst and median ρ over the draws, median
    |bias|, bias spread, median Brier, and for SGAT, hybrid and oracle worlds how many of the issue's
    targets they meet at k (:func:`fidelity_targets` on :func:`episodes_view`; None for others).
    Empty for a result saved before ``by_episodes``."""
    rows = []
    ks = sorted({int(k) for w in res["worlds"].values() for k in (w.get("by_episodes") or {})})
    views = {k: episodes_view(res, k) for k in ks}
    for name, w in res["worlds"].items():
        for k in sorted(int(k) for k in (w.get("by_episodes") or {})):
            s = w["by_episodes"][str(k)]["summary"]
            t = fidelity_targets(views[k], name) if w.get("kind") in ("sgat", "hybrid", "oracle") else []
            rows.append({"world": name, "episodes": k, "rho_worst": s["rho"]["min"], "rho_median": s["rho"]["median"],
                         "abs_bias_median": s["abs_bias_median"], "bias_spread": s["bias"]["spread"],
                         "brier_median": s["brier"]["median"], "targets_met": sum(ok for _, ok, _ in t) if t else None,
                         "targets": len(t) if t else None, "ranking_met": bool(t[0][1]) if t else None})
    return rows


#: Fewest gaits of a group that :func:`group_rows` gives a Spearman ρ (a rank correlation over a
#: handful of gaits says little).
GROUP_MIN_RANK = 8


def gait_groups(res: dict) -> dict[str, list[int]]:
    """The groups of a fidelity panel that has θ files (``--params``): ``drawn`` (θ0 and the gaits
    drawn in the trust region), ``given`` (the θ files) and, where the files have more than one
    name, one group per file name (the last part of the gait's name: ``hybrid_step2`` holds every
    Table I seed's ``opt_seed<k>/thetas/hybrid_step2``).

    Returns:
        ``{group: [indices into res["gaits"]]}`` in that order; empty for a panel without θ files.
    """
    n_given = len(res.get("config", {}).get("params") or [])
    if not n_given:
        return {}
    n = len(res["gaits"])
    given = list(range(n - n_given, n))
    out = {"drawn": list(range(n - n_given)), "given": given}
    by_name: dict[str, list[int]] = {}
    for i in given:
        by_name.setdefault(res["gaits"][i].rsplit("/", 1)[-1], []).append(i)
    if len(by_name) > 1:
        out.update({f"given: {k}": v for k, v in by_name.items()})
    return out


def group_rows(res: dict) -> list[dict]:
    """Each world on each gait group of :func:`gait_groups` (gaits optimized in a training world
    apart from those drawn around θ0: what the world promised for them against what they did).

    Per group and world, over the draws (median [min, max]): the world's mean fitness over the
    group's gaits, its bias (world − real, mean over the gaits) and mean absolute error, the Spearman
    ρ within the group
    and the regret of the world's pick within the group (:func:`experiments.runtime.stats.pick_regret`: the
    real fitness lost by taking the gait the world rates best instead of the group's real best). ρ
    only for groups of at least :data:`GROUP_MIN_RANK` gaits, with the group's ceiling of ρ from the
    real trials' noise (:func:`experiments.runtime.stats.split_half_reliability`). The group's real mean
    fitness (with its standard error over the paired trials) and fall rate come with it.

    Returns:
        ``[{"group", "gaits", "real_fitness", "real_fitness_se", "real_ceiling", "real_falls",
        "world", "fitness", "bias", "mae", "rho", "pick_regret"}]``, each figure of the world a
        ``{"median", "min", "max", "spread"}`` (``rho`` and ``real_ceiling`` None for a small group);
        empty without θ files.
    """
    groups = gait_groups(res)
    if not groups:
        return []
    real_fit = np.asarray(res["real"]["fitness"], dtype=float)
    trials = res["real"].get("fitness_trials")
    falls = np.asarray(res["real"]["fall_rate"], dtype=float)
    seed = int(res["config"].get("seed", 0))
    rows = []
    for group, idx in groups.items():
        ix = np.asarray(idx)
        real = {"group": group, "gaits": len(ix), "real_fitness": float(real_fit[ix].mean()),
                "real_fitness_se": (float(np.std(np.asarray(trials)[ix].mean(0), ddof=1) / math.sqrt(len(trials[0])))
                                    if trials else None),
                "real_ceiling": (split_half_reliability(np.asarray(trials)[ix], seed=seed)["ceiling"]
                                 if trials and len(ix) >= GROUP_MIN_RANK else None),
                "real_falls": float(falls[ix].mean())}
        for name, w in res["worlds"].items():
            fit, bias, mae, rho, regret = [], [], [], [], []
            for d in w["draws"]:
                wf = np.asarray(d["fitness"], dtype=float)[ix]
                fit.append(wf.mean())
                bias.append(float(np.mean(wf - real_fit[ix])))
                mae.append(float(np.mean(np.abs(wf - real_fit[ix]))))
                if len(ix) >= GROUP_MIN_RANK:
                    rho.append(spearman(wf, real_fit[ix]))
                if len(ix) >= 2:
                    regret.append(pick_regret(wf, real_fit[ix]))
            rows.append({**real, "world": name, "fitness": _over_draws(fit), "bias": _over_draws(bias),
                         "mae": _over_draws(mae), "rho": _over_draws(rho) if rho else None,
                         "pick_regret": _over_draws(regret) if regret else None})
    return rows


def format_groups(res: dict) -> list[str]:
    """The text lines of :func:`group_rows` (none for a panel without θ files)."""
    rows = group_rows(res)
    if not rows:
        return []
    lines = ["", "per gait group (drawn: theta0 and the trust-region gaits; given: the --params files, and each file "
                 "name): median [min, max] over the draws (MAE: the median); rho /the group's ceiling from the real trials' noise",
             f"  {'group':30s} {'world':16s} {'gaits':>5s} {'real':>6s} {'world':>19s} {'bias':>20s} {'MAE':>6s} {'rho /ceiling':>25s} "
             f"{'pick regret':>17s}"]
    for r in rows:
        rho = _range_text(r["rho"]) + ("" if r["real_ceiling"] is None else f" /{r['real_ceiling']:.2f}")
        lines.append(f"  {r['group']:30s} {r['world']:16s} {r['gaits']:>5d} {r['real_fitness']:>+6.1f} "
                     f"{_range_text(r['fitness'], '{:+.1f}'):>19s} {_range_text(r['bias'], '{:+.1f}'):>20s} {r['mae']['median']:>6.1f} {rho:>25s} "
                     f"{_range_text(r['pick_regret'], '{:.1f}'):>17s}")
    return lines


def format_episodes(res: dict) -> list[str]:
    """The text lines of :func:`episodes_rows` (none for a result without ``by_episodes``)."""
    rows = episodes_rows(res)
    if not rows:
        return []
    lines = ["", f"against episodes per gait (the first k of every gait's episodes, the seeds of a run with --episodes k; "
                 f"ranking target {ranking_target(res['real']['ceiling']):.2f}):",
             f"  {'world':26s} {'k':>3s} {'rho worst [median]':>19s} {'|bias|':>7s} {'spread':>7s} {'Brier':>6s} {'targets met':>12s}"]
    for r in rows:
        met = "-" if r["targets"] is None else f"{r['targets_met']}/{r['targets']}" + (" (rank)" if r["ranking_met"] else "")
        lines.append(f"  {r['world']:26s} {r['episodes']:>3d} {r['rho_worst']:>8.2f} [{r['rho_median']:.2f}]     "
                     f"{r['abs_bias_median']:>7.1f} {r['bias_spread']:>7.1f} {r['brier_median']:>6.3f} {met:>12s}")
    return lines


def _own(summary: dict) -> str:
    """A world's own-noise ceiling of ρ as 'median [worst]' over its draws, '-' where not measured."""
    c = summary.get("world_ceiling")
    return "-" if c is None else f"{c['median']:.2f} [{c['min']:.2f}]"


def plot(res: dict, path: str) -> None:
    """Predicted against real fitness, one panel per world, one colour per draw; a panel with θ files
    (:func:`gait_groups`) draws the given gaits as triangles, the drawn ones as dots."""
    import matplotlib  # lazy: matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: matplotlib

    worlds = list(res["worlds"].items())
    n = len(worlds)
    cols = min(3, n)
    rows = int(math.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.8 * rows), squeeze=False,
                             layout="constrained")  # leaves room for the suptitle (tight_layout does not)
    real = np.array(res["real"]["fitness"])
    se = np.array(res["real"]["fitness_se"])
    lo = min(real.min(), min(min(d["fitness"]) for _, w in worlds for d in w["draws"])) - 2
    hi = max(real.max(), max(max(d["fitness"]) for _, w in worlds for d in w["draws"])) + 2
    given = np.zeros(len(real), dtype=bool)
    given[gait_groups(res).get("given", [])] = True
    for ax, (name, w) in zip(axes.ravel(), worlds):
        ax.plot([lo, hi], [lo, hi], color="0.6", lw=1, ls="--")
        for d in w["draws"]:
            f = np.asarray(d["fitness"], dtype=float)
            line = ax.errorbar(real[~given], f[~given], xerr=se[~given], fmt="o", ms=3.5, lw=0.6, alpha=0.8,
                               label=f"draw {d['draw']}: ρ {d['rho']:.2f}"
                               if d["rho"] is not None and math.isfinite(d["rho"]) else f"draw {d['draw']}")
            if given.any():
                ax.errorbar(real[given], f[given], xerr=se[given], fmt="^", ms=4.5, lw=0.6, alpha=0.8,
                            color=line[0].get_color())
        if given.any():  # the marker key, in the legend below the draws
            ax.plot([], [], "^", color="0.3", ms=4.5, label="given θ files")
        ax.set_xlim(lo, hi)
        ax.set_ylim(lo, hi)
        ax.set_title(name, fontsize=10)
        ax.set_xlabel("real fitness (mean ± s.e.)")
        ax.set_ylabel("training-world fitness")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=6, loc="upper left")
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    fig.suptitle(f"fidelity: {len(real)} gaits, fitness = speed [cm/s] − 15 per fall; ceiling ρ "
                 f"{res['real']['ceiling']:.2f}", fontsize=10)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


def plot_episodes(res: dict, path: str) -> None:
    """Fidelity against episodes per gait (:func:`episodes_rows`): worst (solid) and median (dashed)
    ρ over the draws with the ranking target, and the bias spread over the draws with its target of 4,
    one line per stochastic world; the deterministic worlds as horizontal lines."""
    import matplotlib  # lazy: matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: matplotlib

    rows = episodes_rows(res)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 4.2), layout="constrained")
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    worlds = list(dict.fromkeys(r["world"] for r in rows))
    for i, name in enumerate(worlds):
        rs = [r for r in rows if r["world"] == name]
        k = [r["episodes"] for r in rs]
        c = colors[i % len(colors)]
        a1.plot(k, [r["rho_worst"] for r in rs], "o-", color=c, label=name)
        a1.plot(k, [r["rho_median"] for r in rs], "o--", color=c, alpha=0.5, ms=3)
        if res["worlds"][name]["summary"]["draws"] > 1:  # a spread needs draws
            a2.plot(k, [r["bias_spread"] for r in rs], "o-", color=c)
    for j, (name, w) in enumerate((n, w) for n, w in res["worlds"].items()
                                  if w.get("kind", n.split(":")[0]) in DETERMINISTIC_KINDS):
        c = colors[(len(worlds) + j) % len(colors)]
        a1.axhline(w["summary"]["rho"]["min"], color=c, lw=1, ls=":", label=f"{name} (deterministic, worst draw)")
        if w["summary"]["draws"] > 1:
            a2.axhline(w["summary"]["bias"]["spread"], color=c, lw=1, ls=":")
    a1.axhline(ranking_target(res["real"]["ceiling"]), color="k", lw=1.2, label="ranking target")
    a1.axhline(res["real"]["ceiling"], color="0.5", lw=1, ls="-.", label="ceiling (real trials' noise)")
    a2.axhline(4.0, color="k", lw=1.2, label="target for the spread (≤ 4)")
    for ax in (a1, a2):
        ax.set_xscale("log", base=2)
        ax.set_xticks(sorted({r["episodes"] for r in rows}), [str(x) for x in sorted({r["episodes"] for r in rows})])
        ax.set_xlabel("episodes per gait in the training world")
        ax.grid(alpha=0.3)
    a1.set_ylabel("Spearman ρ with real fitness\n(solid: worst draw, dashed: median)")
    a2.set_ylabel("bias spread over the draws [fitness points]")
    a2.legend(fontsize=6, loc="best")
    fig.legend(*a1.get_legend_handles_labels(), loc="outside right upper", fontsize=7)  # one legend, both panels
    fig.suptitle(f"fidelity against episodes per gait: {len(res['gaits'])} gaits × {res['real']['trials']} real trials",
                 fontsize=10)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


__all__ = ["DEFAULT_WORLDS", "KINDS", "Fidelity", "FidelityConfig", "WorldSpec", "episode_counts", "episodes_rows", "episodes_view",
           "drawn_panel", "format_ci", "p_text", "paired_rows", "paired_test", "world_pairs",
           "fidelity_targets", "first_world", "format_table",
           "parse_world", "plot", "plot_episodes", "ranking_target"]
