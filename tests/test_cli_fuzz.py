"""CLI fuzz: every subcommand × every numeric and path option × bad values (negative, NaN, infinite,
huge, wrong type, missing file, directory, unwritable path) ends with exit status 2, one line on
stderr naming the flag, no traceback, and no file or folder left behind."""

import argparse
import os

import pytest

import experiments.cli.argtypes as A
from experiments import cli

NUMERIC_BAD = ["-5", "nan", "inf", "1e12", "abc"]
UNWRITABLE = "/dev/null/sub/x"  # /dev/null is not a directory: nothing can be created below it
# what a subcommand needs besides the fuzzed option for argparse to reach the option (required options)
REQUIRED = {"diagnose": ["--real", ".", "--out", "rep"], "excite": ["--out", "logs"]}


def _subparsers() -> dict[str, argparse.ArgumentParser]:
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def _cases():
    for cmd, p in _subparsers().items():
        for act in p._actions:
            flag = act.option_strings[0] if act.option_strings else None
            t = act.type
            if isinstance(t, A.Number):
                bad = NUMERIC_BAD
            elif t is A.out_file:
                bad = ["<dir>", UNWRITABLE, "<dir>/"]
            elif t is A.out_dir:
                bad = ["<file>", UNWRITABLE]
            elif t is A.in_file:
                bad = ["<missing>", "<dir>"]
            elif t is A.in_path:
                bad = ["<missing>"]
            elif t is A.in_dir:
                bad = ["<missing>", "<file>"]
            elif t in (A.world, A.worlds):
                bad = ["moon", "sgat:alpha=2", "sgat:shadow=0.1", "sgat:alpha", "hybrid:delay=auto:delay=1"]
            elif t is A.profile:
                bad = ["moon"]
            else:
                continue
            for v in bad:
                yield pytest.param(cmd, flag, v, id=f"{cmd}-{flag or act.dest}-{v}")


def _tree(root) -> set[str]:
    return {os.path.relpath(os.path.join(d, f), root) for d, ds, fs in os.walk(root) for f in fs + ds}


def _run(capsys, tmp_path, monkeypatch, argv):
    monkeypatch.chdir(tmp_path)
    before = _tree(tmp_path)
    rc = cli.main(argv)
    out, err = capsys.readouterr()
    return rc, out, err, _tree(tmp_path) - before


def test_every_number_option_has_a_bounded_range():
    loose = []
    for cmd, p in _subparsers().items():
        for act in p._actions:
            if act.type in (int, float):
                loose.append(f"{cmd} {act.option_strings}: plain {act.type.__name__}")
            elif isinstance(act.type, A.Number) and (act.type.lo is None or act.type.hi is None):
                loose.append(f"{cmd} {act.option_strings}: unbounded")
    assert not loose, "numeric options without a range (experiments.cli.argtypes): " + "; ".join(loose)


@pytest.mark.parametrize("cmd,flag,value", list(_cases()))
def test_bad_value_is_one_line_exit_2_and_leaves_nothing(cmd, flag, value, tmp_path, monkeypatch, capsys):
    (tmp_path / "a_dir").mkdir()
    (tmp_path / "a_file.json").write_text("{}")
    value = {"<dir>": "a_dir", "<dir>/": "new_dir/", "<file>": "a_file.json", "<missing>": "no_such_file.json"}.get(value, value)
    argv = [cmd] + [a for a in REQUIRED.get(cmd, []) if flag not in REQUIRED.get(cmd, [])]
    argv += [flag, value] if flag else [value]
    rc, out, err, new = _run(capsys, tmp_path, monkeypatch, argv)
    assert rc == 2, (argv, rc, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"sgatwalk {cmd}: error:"), err
    assert "Traceback" not in err
    if flag:
        assert flag in lines[0], f"the message does not name {flag}: {lines[0]}"
    assert not new, f"left behind: {sorted(new)}"


@pytest.mark.parametrize("argv,needle", [
    (["walk", "--terrain", "lumpy", "--amplitude", "0.5"], "amplitude"),       # 0.5 m bumps: beyond lumpy's range
    (["walk", "--amplitude", "0.01"], "--terrain"),                            # amplitude without a terrain
    (["stand", "--seconds", "0"], "--seconds"),
    (["optimize", "--methods", "sgat,bogus"], "bogus"),
    (["stress", "--terrain", "lumpy", "--amplitude", "0:0.01:0"], "--amplitude"),
    (["fidelity", "--worlds", "sgat:alpha=2"], "alpha"),
    (["nosuchcommand"], "invalid choice"),
])
def test_bad_combinations_are_one_line_exit_2(argv, needle, tmp_path, monkeypatch, capsys):
    rc, out, err, new = _run(capsys, tmp_path, monkeypatch, argv)
    assert rc == 2, (argv, rc, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "error:" in lines[0] and needle in lines[0], err
    assert not new, f"left behind: {sorted(new)}"


def test_world_options_are_checked_at_the_boundary():
    """A world's ``hidden`` option: sizes joined by x, or 0 for linear grounding models; anything else
    is an argparse error naming it."""
    assert A.world("sgat:hidden=64x64") == "sgat:hidden=64x64" and A.world("sgat:hidden=0") == "sgat"
    assert A.worlds("sgat,gat:alpha=0.5") == ("sgat", "gat")
    for bad in ("sgat:hidden=", "sgat:hidden=0x3", "sgat:hidden=64x", "sgat:hidden=5000"):
        with pytest.raises(argparse.ArgumentTypeError, match="hidden"):
            A.world(bad)


def test_help_exits_0(capsys):
    assert cli.main(["walk", "--help"]) == 0
    assert "--seconds" in capsys.readouterr().out
