"""The design's layers hold (docs/architecture.md): every import of the project's own code points one way.

Layers, top down::

    tools                      renders and checks the docs from saved results; imports nothing of the project
    benchmarks                 scripts that print measured ratios
    experiments.cli            argparse -> an experiment's config -> its run; no experiment logic
    experiments.<experiment>   optimize, fidelity, table1, compare, stress, gym, cliff, demos
    experiments.viz            Rerun logging of recordings
    experiments.runtime        worlds, tasks, executors, run directories, seeds, fitness, statistics,
                               the grounding and identification steps
    sgat, sysid                grounding; diagnosis
    envs, walk_engine          the two worlds; the ZMP walk engine
    robots, terrain            robot models; heightfields
    common                     NumPy and the standard library only

An experiment reads another only through its public API and typed results: ``table1`` runs
optimizations through ``experiments.optimize`` (the package's ``__init__``: config, ``Optimizer``,
result types) and ``compare`` reads saved fidelity results through ``experiments.fidelity.results``. Function-level imports count too. (That the walk engine loads no
physics engine at run time is tests/test_walk_engine.py's; that the CLI loads none is checked here.)
"""

import ast
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
LIBS = ("common", "robots", "terrain", "envs", "walk_engine", "sgat", "sysid")
EXPERIMENTS = ("optimize", "fidelity", "table1", "compare", "stress", "gym", "cliff", "demos", "stochasticity")
BELOW_EXPERIMENTS = set(LIBS) | {"experiments.runtime", "experiments.viz"}
#: Node -> the nodes it may import.
ALLOWED: dict[str, set[str]] = {
    "common": set(),
    "robots": {"common"},
    "terrain": {"common"},
    "envs": {"common", "robots", "terrain"},
    "walk_engine": {"common", "robots"},
    "sgat": {"common", "envs", "robots", "terrain"},
    "sysid": {"common", "envs", "robots", "terrain"},
    "experiments.runtime": set(LIBS),
    "experiments.viz": set(LIBS) | {"experiments.runtime"},
    **{f"experiments.{e}": set(BELOW_EXPERIMENTS) for e in EXPERIMENTS},
    "experiments.cli": set(BELOW_EXPERIMENTS) | {f"experiments.{e}" for e in EXPERIMENTS},
    "tools": set(),
    "benchmarks": set(BELOW_EXPERIMENTS) | {f"experiments.{e}" for e in EXPERIMENTS} | {"experiments.cli", "tools"},
}
#: The modules through which one experiment may use another (its public API and result types).
RESULTS_OF = {"experiments.table1": {"experiments.optimize", "experiments.optimize.results"},
              "experiments.compare": {"experiments.fidelity.results"},
              # a study composes whole runs of other experiments
              "experiments.stochasticity": {"experiments.fidelity.config", "experiments.fidelity.run",
                                            "experiments.table1.config", "experiments.table1.run"}}


def _node(module: str) -> str | None:
    """The layer node a module belongs to (None: not the project's)."""
    parts = module.split(".")
    if parts[0] == "experiments":
        return ".".join(parts[:2]) if len(parts) > 1 else "experiments"
    return parts[0] if parts[0] in ALLOWED else None


def _python_files(top: str):
    for dirpath, dirnames, filenames in os.walk(os.path.join(ROOT, top)):
        dirnames[:] = sorted(d for d in dirnames if d != "__pycache__")
        for f in sorted(filenames):
            if f.endswith(".py"):
                yield os.path.join(dirpath, f)


def _module_of(path: str) -> str:
    rel = os.path.relpath(path, ROOT)[:-3].replace(os.sep, ".")
    return rel[:-len(".__init__")] if rel.endswith(".__init__") else rel


def _imports(path: str):
    """(imported module, line) of every absolute import in the file, relative ones resolved."""
    mod = _module_of(path)
    pkg = mod if path.endswith("__init__.py") else mod.rsplit(".", 1)[0]
    for node in ast.walk(ast.parse(open(path).read())):
        if isinstance(node, ast.Import):
            for a in node.names:
                yield a.name, node.lineno
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = pkg.split(".")[: len(pkg.split(".")) - node.level + 1]
                base = ".".join(up + ([base] if base else []))
            for a in node.names:
                yield (f"{base}.{a.name}" if base else a.name), node.lineno


def test_import_arrows_point_one_way():
    bad = []
    for top in ("common", "robots", "terrain", "envs", "walk_engine", "sgat", "sysid", "experiments", "tools",
                "benchmarks"):
        for path in _python_files(top):
            src = _node(_module_of(path))
            if src in (None, "experiments"):
                continue
            for target, line in _imports(path):
                dst = _node(target)
                if dst is None or dst == src:
                    continue
                ok = dst in ALLOWED[src]
                if src in RESULTS_OF and dst.startswith("experiments.") and dst not in BELOW_EXPERIMENTS:
                    # the module itself, or a name imported from it
                    ok = any(target == r or target.rsplit(".", 1)[0] == r for r in RESULTS_OF[src])
                if not ok:
                    bad.append(f"{os.path.relpath(path, ROOT)}:{line} imports {target} ({src} -> {dst})")
    assert not bad, "imports against the design:\n" + "\n".join(bad)


def test_every_package_file_is_in_a_layer():
    stray = [os.path.relpath(p, ROOT) for p in _python_files("experiments")
             if _node(_module_of(p)) not in ALLOWED and _module_of(p) != "experiments"]
    assert not stray, f"modules of experiments/ outside every layer: {stray}"


def test_the_cli_loads_no_physics_engine_or_torch():
    code = ("import sys, experiments.cli as c; c.build_parser(); "
            "print(sorted(m for m in ('mujoco', 'pybullet', 'torch', 'scipy', 'sgat', 'sysid', 'envs') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True).stdout
    assert out.strip() == "[]", f"building the sgatwalk parser imported {out.strip()}"
