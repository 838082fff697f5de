"""The design's import arrows hold (docs/architecture.md): experiments -> sgat, sysid -> envs -> robots,
terrain; experiments -> walk_engine -> robots; every package -> common. Function-level imports count too. (That the walk engine
loads no physics engine at run time is tests/test_walk_engine.py's.)"""

import ast
import os

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ALLOWED = {
    "common": set(),
    "robots": {"common"},
    "terrain": {"common"},
    "envs": {"common", "robots", "terrain"},
    "walk_engine": {"common", "robots"},
    "sgat": {"common", "envs", "robots", "terrain"},
    "sysid": {"common", "envs", "robots", "terrain"},
    "experiments": {"common", "envs", "robots", "terrain", "walk_engine", "sgat", "sysid"},
}


def _imports(package: str) -> dict[str, set[str]]:
    out: dict[str, set[str]] = {}
    files = []
    for dirpath, dirnames, filenames in os.walk(os.path.join(ROOT, package)):  # subpackages too (experiments.viz)
        dirnames[:] = sorted(d for d in dirnames if d != "__pycache__")
        files += [os.path.relpath(os.path.join(dirpath, f), os.path.join(ROOT, package))
                  for f in sorted(filenames) if f.endswith(".py")]
    for f in files:
        tree = ast.parse(open(os.path.join(ROOT, package, f)).read())
        for node in ast.walk(tree):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module] if isinstance(node, ast.ImportFrom) and node.module and node.level == 0 else []
            for n in names:
                top = n.split(".")[0]
                if top in ALLOWED and top != package:
                    out.setdefault(top, set()).add(f)
    return out


def test_import_arrows_point_one_way():
    bad = {p: {d: sorted(fs) for d, fs in _imports(p).items() if d not in ALLOWED[p]} for p in ALLOWED}
    assert not any(bad.values()), f"imports against the design: {bad}"

