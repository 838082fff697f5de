"""``sgatwalk cliff`` through the CLI dispatcher (experiments.cli.main)."""

from __future__ import annotations

import csv
import json

import pytest

from experiments.cli import main
from experiments.cliff.run import parse_noise

FAST = ["--episodes", "2000", "--real-episodes", "2000"]


def test_json_result_and_files(tmp_path, capsys):
    out = tmp_path / "cliff"
    rc = main(["cliff", "--noise", "0,0.4", *FAST, "--seed", "1", "--out", str(out), "--json"])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    result = json.loads(captured.out)
    rows = result["rows"]
    assert [r["noise"] for r in rows] == [0.0, 0.4]
    keys = {"noise", "gat_return", "gat_se", "sgat_return", "sgat_se", "optimal_return"}
    assert all(keys <= r.keys() for r in rows)
    assert rows[1]["sgat_return"] > rows[1]["gat_return"]
    assert result["episodes"] == 2000 and result["seed"] == 1
    with open(out / "cliff.csv", newline="") as f:
        table = list(csv.DictReader(f))
    assert [float(r["noise"]) for r in table] == [0.0, 0.4]
    assert float(table[1]["sgat_return"]) == pytest.approx(rows[1]["sgat_return"], rel=1e-5)
    for png in ("cliff.png", "cliff_paths.png"):
        assert (out / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(p.name for p in out.iterdir()) == ["cliff.csv", "cliff.png",
                                                    "cliff_paths.png"]  # no temp files left


def test_human_table(tmp_path, capsys):
    rc = main(["cliff", "--noise", "0:0.5:2", *FAST, "--out", str(tmp_path)])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    lines = captured.out.splitlines()
    assert any("GAT" in ln and "SGAT" in ln and "optimum" in ln for ln in lines)
    assert any(ln.strip().startswith("0.50") and "±" in ln for ln in lines)
    assert not captured.out.lstrip().startswith("{")


def test_same_seed_same_rows(tmp_path, capsys):
    args = ["cliff", "--noise", "0.2", *FAST, "--json"]
    main([*args, "--out", str(tmp_path / "a")])
    first = json.loads(capsys.readouterr().out)["rows"]
    main([*args, "--out", str(tmp_path / "b")])
    assert json.loads(capsys.readouterr().out)["rows"] == first


def test_parse_noise():
    assert parse_noise("0:1:11") == [round(i / 10, 12) for i in range(11)]
    assert parse_noise("0.5") == [0.5]
    assert parse_noise(" 0, 0.25 ,1") == [0.0, 0.25, 1.0]


@pytest.mark.parametrize("argv, needle", [
    (["--noise", "1.5"], "not a probability"),
    (["--noise=-0.1,0.5"], "not a probability"),
    (["--noise", "-0.1"], "not a probability"),
    (["--noise", "0:2:3"], "not a probability"),
    (["--noise", "0:1"], "malformed"),
    (["--noise", "a,b"], "malformed"),
    (["--noise", "0,,1"], "malformed"),
    (["--noise", "0:1:0"], "count"),
    (["--noise", "0:1:2.5"], "count"),
    (["--episodes", "0"], "--episodes"),
    (["--episodes", "-5"], "--episodes"),
    (["--real-episodes", "0"], "--real-episodes"),
    (["--explore", "1.5"], "--explore"),
])
def test_bad_input_is_one_clear_line(tmp_path, capsys, argv, needle):
    rc = main(["cliff", *argv, "--out", str(tmp_path / "o")])
    captured = capsys.readouterr()
    assert rc == 2
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("sgatwalk cliff: error:")
    assert needle in err[0]
    assert "Traceback" not in captured.err
    assert not (tmp_path / "o").exists()


def test_out_must_be_a_directory(tmp_path, capsys):
    target = tmp_path / "file"
    target.write_text("x")
    assert main(["cliff", "--noise", "0", "--out", str(target)]) == 2
    assert "not a directory" in capsys.readouterr().err
    assert target.read_text() == "x"
