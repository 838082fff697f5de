"""Training worlds: one vocabulary for every command that trains or scores in a world.

A training world is written ``kind[:option=value...]``, e.g. ``sgat``, ``sgat:alpha=0.3:ensemble=1``,
``hybrid:delay=auto`` or ``real:mean=1``. The same text names the world in ``sgatwalk optimize
--methods``, ``sgatwalk table1 --methods``, ``sgatwalk fidelity --worlds`` and in every result they
save; :func:`parse_world` reads it and :attr:`WorldSpec.name` writes it back in one canonical form
(the options that differ from their defaults, in the order of :data:`OPTIONS`).

Kinds (:data:`KINDS`):

==============  =========================================================================================
``sim``         the plain MuJoCo sim (deterministic)
``ane``         the sim with Gaussian noise on the leg targets: the action-noise envelope (Jakobi,
                Husbands and Harvey, ECAL 1995), the paper's ANE baseline
``gat``         the sim grounded by an action transformer with a deterministic forward model (GAT:
                Hanna and Stone, AAAI 2017)
``sgat``        the sim grounded with a stochastic forward model, sampled (SGAT: Desai et al., IROS 2020)
``identified``  the sim with the physics ``sgatwalk diagnose`` identified from excitation logs of the
                real world built in (``sysid.identified.IdentifiedSimEnv``)
``hybrid``      SGAT grounding on top of the identified sim: the transformer learns only what the
                diagnosis could not name
``real``        the PyBullet real world itself, on fresh seeds: what a world that is exactly right
                gets (a bound; it costs real trials)
==============  =========================================================================================

Every option is declared once in :data:`OPTIONS` with the kinds that take it, its range, its
default and its help; an unknown option, an option of another kind or a value out of range is a
``ValueError`` that names it.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from typing import Any, Callable

#: World kinds and what each is (the module docstring's table).
KINDS: dict[str, str] = {
    "sim": "the plain MuJoCo sim",
    "ane": "the sim with Gaussian noise on the leg targets (action-noise envelope)",
    "gat": "the sim grounded by GAT (deterministic forward model)",
    "sgat": "the sim grounded by SGAT (stochastic forward model, sampled)",
    "identified": "the sim with the physics sgatwalk diagnose identified from excitation logs of the real world",
    "hybrid": "SGAT grounding on top of the identified sim",
    "real": "the PyBullet real world itself (fresh seeds; a bound)",
}
#: Kinds grounded by a learned action transformer.
GROUNDED = ("gat", "sgat", "hybrid")
#: Kinds built on the real world's identification (``sgatwalk diagnose`` of excitation logs).
IDENTIFIED = ("identified", "hybrid")
#: Kinds that learn from real data or add noise to the sim as a stand-in for it (everything but the
#: plain sim and the real world itself): the worlds a fidelity run pairs against the real world.
LEARNED = ("ane", "gat", "sgat", "identified", "hybrid")


def parse_hidden(text: str) -> tuple[int, ...]:
    """Hidden layer sizes of the grounding models: ``64x64`` -> (64, 64); ``0`` -> () (linear models).

    Raises:
        ValueError: anything else (sizes outside 1..4096, empty parts).
    """
    t = str(text).strip().lower()
    if t == "0":
        return ()
    try:
        sizes = tuple(int(h) for h in t.split("x"))
    except ValueError:
        sizes = ()
    if not sizes or any(not 1 <= h <= 4096 for h in sizes):
        raise ValueError(f"hidden layers must look like 64x64 (sizes 1 to 4096) or 0 (linear), got {text!r}")
    return sizes


def _number(kind: type, lo: float, hi: float) -> Callable[[str], Any]:
    """A parser of an int or float option in [lo, hi] (finite)."""
    def parse(text: str):
        try:
            v = int(text, 10) if kind is int else float(text)
        except (TypeError, ValueError):
            raise ValueError(f"expected {'an integer' if kind is int else 'a number'} in [{lo:g}, {hi:g}], got {text!r}") \
                from None
        if not (math.isfinite(v) and lo <= v <= hi):
            raise ValueError(f"must be in [{lo:g}, {hi:g}], got {text}")
        return v
    return parse


def _flag(text: str) -> bool:
    if text not in ("0", "1"):
        raise ValueError(f"expected 0 or 1, got {text!r}")
    return text == "1"


def _choice(*values: str) -> Callable[[str], str]:
    def parse(text: str) -> str:
        if text not in values:
            raise ValueError(f"expected {' or '.join(values)}, got {text!r}")
        return text
    return parse


def _delay(text: str) -> int | str:
    return "auto" if text == "auto" else _number(int, 0, 10)(text)


def _text(value: Any) -> str:
    """An option value as it is written in a world's name."""
    if isinstance(value, bool):
        return str(int(value))
    if isinstance(value, tuple):
        return "x".join(map(str, value)) if value else "0"
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


@dataclass(frozen=True)
class Option:
    """One world option: its name in the text form, the kinds that take it, how its text is read
    (raises ValueError), its default per kind, its unit and its help line."""

    name: str
    kinds: tuple[str, ...]
    parse: Callable[[str], Any]
    default: Callable[[str], Any]
    help: str
    unit: str = ""


#: Every world option, in the order a world's name lists them. Grounding options follow the paper
#: (Algorithm 1) and its code; the defaults are the project's (docs/decisions.md says why each).
OPTIONS: tuple[Option, ...] = (
    Option("alpha", GROUNDED, _number(float, 0.0, 1.0), lambda k: 0.1 if k == "hybrid" else 0.5,
           "blend ã = (1-α) a + α g(s, a) of the agent's and the grounded action (1: the paper's formula)"),
    Option("method", ("hybrid",), _choice("sgat", "gat"), lambda k: "sgat",
           "the grounding on top of the identified sim: sgat or gat"),
    Option("ensemble", GROUNDED, _number(int, 1, 100), lambda k: 5,
           "forward/inverse model pairs fitted on bootstrap resamples; SGAT draws one per episode"),
    Option("hidden", GROUNDED, parse_hidden, lambda k: (),
           "hidden layers of both models, e.g. 64x64 (the paper's tanh networks); 0: linear models"),
    Option("epochs", GROUNDED, _number(int, 1, 100_000), lambda k: 150, "maximum training epochs of each model"),
    Option("history", GROUNDED, _number(int, 1, 10), lambda k: 6,
           "frames of state history both models see (1: the paper's s_t alone)"),
    Option("mixture", ("sgat", "hybrid"), _number(int, 1, 10), lambda k: 1,
           "SGAT's forward model as a mixture of K Gaussians (the paper's footnote; 1: one Gaussian)"),
    Option("delay", GROUNDED, _delay, lambda k: 0,
           "actuation delay [control steps] both models bridge; auto (hybrid): the identified latency"),
    Option("real", GROUNDED, _number(int, 1, 1000), lambda k: 4, "real walks per grounding step"),
    Option("sim", GROUNDED, _number(int, 1, 1000), lambda k: 4, "sim walks with exploration noise per grounding step"),
    Option("explore", GROUNDED, _number(float, 0.0, 1.0), lambda k: 0.02,
           "exploration noise of the sim walks: std of Gaussian noise on the leg targets", "rad"),
    Option("ane", ("ane",) + GROUNDED[:2] + IDENTIFIED, _number(float, 0.0, 1.0), lambda k: 0.05 if k == "ane" else 0.0,
           "std of the action-noise envelope's Gaussian noise on the leg targets (0: none)", "rad"),
    Option("mean", ("real",), _flag, lambda k: False,
           "1: the real world with every effect at the middle of its range (its mean physics, one point)"),
)
_BY_NAME = {o.name: o for o in OPTIONS}


@dataclass(frozen=True)
class WorldSpec:
    """One training world: its kind and the options set away from their defaults.

    Build it with :func:`parse_world`; read an option with :meth:`get`.

    Attributes:
        kind: a key of :data:`KINDS`.
        options: ``((name, value), ...)`` of the options that differ from their defaults, in the
            order of :data:`OPTIONS`.
    """

    kind: str
    options: tuple[tuple[str, Any], ...] = ()

    def get(self, name: str) -> Any:
        """The value of option ``name`` (its default unless set).

        Raises:
            KeyError: ``name`` is no option of this kind (a bug in the caller).
        """
        opt = _BY_NAME[name]
        if self.kind not in opt.kinds:
            raise KeyError(f"world kind {self.kind!r} has no option {name!r}")
        return dict(self.options).get(name, opt.default(self.kind))

    @property
    def name(self) -> str:
        """The canonical text of the world (``kind[:option=value...]``)."""
        return ":".join([self.kind] + [f"{k}={_text(v)}" for k, v in self.options])

    def __str__(self) -> str:
        return self.name

    @property
    def key(self) -> str:
        """A short stable identifier of the world for file names and caches: kind and a hash of the name."""
        return f"{self.kind}-{hashlib.sha1(self.name.encode()).hexdigest()[:10]}"

    @property
    def grounded(self) -> bool:
        """Grounded by a learned action transformer (gat, sgat, hybrid)."""
        return self.kind in GROUNDED

    @property
    def needs_identification(self) -> bool:
        """Built on the real world's identification (identified, hybrid)."""
        return self.kind in IDENTIFIED

    @property
    def noise(self) -> float:
        """Std [rad] of the action-noise envelope on the leg targets (0: none)."""
        return float(self.get("ane")) if self.kind in _BY_NAME["ane"].kinds else 0.0

    @property
    def deterministic(self) -> bool:
        """Whether every episode of a gait is the same whatever its seed, so that one episode is the
        world's answer: the plain sim (MuJoCo is deterministic) and GAT on it (its members averaged)."""
        return self.kind in ("sim", "gat") and not self.noise

    @property
    def per_draw(self) -> bool:
        """Whether the world is built anew for every draw of real data (a fidelity run's draws): it
        learns from real data, or it is the real world on fresh seeds per draw."""
        return self.grounded or self.needs_identification or self.kind == "real"

    def without(self, *names: str) -> WorldSpec:
        """This world with options ``names`` back at their defaults (``sgat:ane=0.05`` -> ``sgat``)."""
        return WorldSpec(self.kind, tuple((k, v) for k, v in self.options if k not in names))

    def grounding_config(self, delay: int | None = None):
        """The :class:`sgat.grounding.GroundingConfig` of a grounded world (None for the others).

        Args:
            delay: the delay [control steps] to use where the world's ``delay`` is ``auto`` (the
                identified latency, :func:`experiments.runtime.grounding.identified_delay`).

        Raises:
            ValueError: ``delay=auto`` without ``delay``.
        """
        if not self.grounded:
            return None
        from sgat.grounding import GroundingConfig  # lazy: sgat loads torch

        d = self.get("delay")
        if d == "auto":
            if delay is None:
                raise ValueError(f"world {self.name!r}: delay=auto needs the identified latency")
            d = delay
        method = self.get("method") if self.kind == "hybrid" else self.kind
        return GroundingConfig(alpha=float(self.get("alpha")), method=method, hidden=tuple(self.get("hidden")),
                               ensemble=int(self.get("ensemble")), max_epochs=int(self.get("epochs")),
                               components=int(self.get("mixture")) if method == "sgat" else 1, delay=int(d))


def parse_world(text: str) -> WorldSpec:
    """A world from its text ``kind[:option=value...]`` (module docstring).

    Raises:
        ValueError: an unknown kind, an option the kind does not take, a repeated option, or a bad
            value; the message names it and what is allowed.
    """
    parts = [p.strip() for p in str(text).split(":")]
    kind = parts[0]
    if kind not in KINDS:
        raise ValueError(f"unknown world {kind!r}; choose from {', '.join(KINDS)} (options after ':', e.g. sgat:alpha=0.3)")
    given: dict[str, Any] = {}
    for part in parts[1:]:
        name, eq, value = (s.strip() for s in part.partition("="))
        if not eq:
            raise ValueError(f"world {text!r}: option {part!r} is not name=value")
        opt = _BY_NAME.get(name)
        if opt is None or kind not in opt.kinds:
            takes = [o.name for o in OPTIONS if kind in o.kinds]
            raise ValueError(f"world {text!r}: {kind} has no option {name!r}"
                             + (f" (its options: {', '.join(takes)})" if takes else " (it takes no options)"))
        if name in given:
            raise ValueError(f"world {text!r}: option {name!r} given twice")
        try:
            given[name] = opt.parse(value)
        except ValueError as exc:
            raise ValueError(f"world {text!r}: {name}: {exc}") from None
    if given.get("delay") == "auto" and kind != "hybrid":
        raise ValueError(f"world {text!r}: delay=auto bridges the identified latency: hybrid only")
    if kind == "hybrid" and given.get("method") == "gat" and given.get("mixture", 1) != 1:
        raise ValueError(f"world {text!r}: mixture shapes SGAT's stochastic forward model, not GAT's")
    opts = tuple((o.name, given[o.name]) for o in OPTIONS if o.name in given and given[o.name] != o.default(kind))
    return WorldSpec(kind, opts)


def parse_worlds(texts) -> list[WorldSpec]:
    """Worlds from a comma-separated text or a list of texts (a comma inside a list item separates too).

    Raises:
        ValueError: a bad world (:func:`parse_world`), none given, or one world given twice (also
            under another spelling).
    """
    items = [texts] if isinstance(texts, str) else list(texts)
    specs = [parse_world(t) for item in items for t in str(item).split(",") if t.strip()]
    if not specs:
        raise ValueError("no world given")
    names = [s.name for s in specs]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ValueError(f"a world given twice: {', '.join(twice)}")
    return specs


def options_help(kind: str | None = None) -> str:
    """The options table as help text: one line per option (``name  kinds  help [unit]``)."""
    rows = [o for o in OPTIONS if kind is None or kind in o.kinds]
    return "\n".join(f"  {o.name:9s} ({', '.join(o.kinds)}) {o.help}" + (f" [{o.unit}]" if o.unit else "") for o in rows)




# ------------------------------------------------------------------------------ building worlds
#: Worlds kept per process (a fidelity run builds one identified world per draw; an effect sweep one
#: real world per value): the oldest beyond these are closed.
WORLD_CACHE = 8
_ENVS: dict = {}
_TRANSFORMERS: dict = {}


def mean_profile(profile):
    """``profile`` (an ``envs.effects.RealProfile``) with every effect fixed at the middle of its
    range, named ``"<name>:mean"``: the real world's mean physics without its spread from episode to
    episode (the terrain's shape stays random per episode; its amplitude is fixed too). What a
    training world that identified the real physics exactly, as one point, can at best be."""
    import dataclasses

    from envs.effects import EFFECTS  # lazy: loads the engines

    mids = {f: ((lo + hi) / 2.0,) * 2 for f in EFFECTS for lo, hi in [getattr(profile, f)]}
    return dataclasses.replace(profile, name=f"{profile.name}:mean", **mids)


def real_profile(profile, robot):
    """The real world's profile a task names: a name or dict as it is (``envs.effects.get_profile``
    resolves it for ``robot``), ``"<name>:mean"`` as :func:`mean_profile` of that profile.

    Raises:
        ValueError: an unknown form after ``:``, or what ``get_profile`` raises.
    """
    from envs.effects import get_profile  # lazy: loads the engines

    if not isinstance(profile, str):
        return get_profile(profile, robot)
    base, sep, form = profile.partition(":")
    if not sep:
        return get_profile(profile, robot)
    if form != "mean":
        raise ValueError(f"profile {profile!r}: unknown form {form!r} (NAME or NAME:mean)")
    return mean_profile(get_profile(base, robot))


def world_env(task):
    """The physical world of an :class:`experiments.runtime.tasks.EpisodeTask`, built once per process
    and kept (at most :data:`WORLD_CACHE` at a time): ``envs.SimWorld``, ``envs.RealWorld`` with the
    task's profile on the real world's random lumpy ground, or ``sysid.identified.IdentifiedSimEnv``
    with the effects and uneven ground of the task's diagnosis reports.

    Raises:
        ValueError: an unknown profile; what loading the reports raises.
    """
    import json

    from robots import get_robot

    # a world that lays given heightfields down keeps the last one as its ground: its own instance, so
    # that the tasks on the world's own ground never walk on a stress test's field
    key = (task.world, json.dumps(task.profile, sort_keys=True) if task.world == "real" else None, task.identified,
           task.robot, task.terrain is not None, task.stochasticity)
    if key not in _ENVS:
        if len(_ENVS) >= WORLD_CACHE:
            for env in _ENVS.values():
                env.close()
            _ENVS.clear()
        robot = get_robot(task.robot)
        if task.world == "real":
            from envs import RealWorld  # lazy: loads the engines

            _ENVS[key] = RealWorld(robot, profile=real_profile(task.profile, robot), terrain="lumpy",
                                   stochasticity=task.stochasticity)
        elif task.world == "identified":
            from sysid.identified import IdentifiedSimEnv, load_identified  # lazy: loads the engines

            terms, rms = load_identified(list(task.identified), confounded=False)
            _ENVS[key] = IdentifiedSimEnv(terms, rms)
        else:
            from envs import SimWorld  # lazy: loads the engines

            _ENVS[key] = SimWorld(robot)
    return _ENVS[key]


def load_transformer(path: str):
    """The ``sgat.ActionTransformer`` saved in ``path``, loaded once per process (reloaded when its
    ``transformer.json`` changes).

    Raises:
        FileNotFoundError, sgat.models.ModelFileError: what ``ActionTransformer.load`` raises.
    """
    import os

    from sgat.transformer import ActionTransformer  # lazy: sgat loads torch

    key = (path, os.path.getmtime(os.path.join(path, "transformer.json")))
    if key not in _TRANSFORMERS:
        _TRANSFORMERS.clear()
        _TRANSFORMERS[key] = ActionTransformer.load(path)
    return _TRANSFORMERS[key]


def task_env(task):
    """The world an episode task walks: :func:`world_env`, on the task's heightfield if it names one,
    with the task's action noise on the leg targets (``envs.wrappers.ActionMismatch``, seeded by the
    episode), grounded by the task's transformer (``sgat.GroundedEnv``) if it has one."""
    import gymnasium as gym

    env = world_env(task)
    if task.terrain is not None:
        hf = terrain_field(*task.terrain)

        class OnTerrain(gym.Wrapper):  # reset always lays the task's field down
            def reset(self, *, seed=None, options=None):
                return self.env.reset(seed=seed, options={**(options or {}), "terrain": hf})

        env = OnTerrain(env)
    if task.action_noise > 0:
        from envs.wrappers import ActionMismatch  # lazy: loads the engines
        from experiments.runtime.grounding import walk_spec  # lazy: loads torch (sgat)

        env = ActionMismatch(env, noise_std=float(task.action_noise), index=walk_spec(1, task.robot).action_index,
                             seed=task.seed)
    if task.transformer:
        from sgat.transformer import GroundedEnv  # lazy: sgat loads torch

        env = GroundedEnv(env, load_transformer(task.transformer))
    return env


_TERRAINS: dict = {}


def terrain_field(kind: str, seed: int, level: float):
    """The heightfield of a (kind, terrain seed, level) (``terrain.make``): identical in every process
    and world (the last 16 kept)."""
    key = (str(kind), int(seed), float(level))
    if key not in _TERRAINS:
        from terrain import make

        if len(_TERRAINS) >= 16:
            _TERRAINS.pop(next(iter(_TERRAINS)))
        _TERRAINS[key] = make(key[0], seed=key[1], amplitude=key[2])
    return _TERRAINS[key]


__all__ = ["GROUNDED", "IDENTIFIED", "KINDS", "LEARNED", "OPTIONS", "WORLD_CACHE", "Option", "WorldSpec",
           "load_transformer", "mean_profile", "options_help", "parse_hidden", "parse_world", "parse_worlds", "real_profile",
           "task_env", "terrain_field", "world_env"]
