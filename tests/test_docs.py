"""The docs check (``python -m tools.docs --check``) on the repository, and its renderer and checks on
small pages made here."""

from __future__ import annotations

import json

import pytest

from tools import docs

V = "<!-- value r:x -->1.5<!-- /value -->"  # a current value marker, so that a page names r.json
STAMP = {"commit": "0123456789ab", "cpu": "Test CPU", "cores": 2, "date": "2026-01-01"}


def _repo(tmp_path, pages: dict[str, str], results: dict[str, dict] | None = None):
    """A repository folder with ``pages`` (path -> text) and ``docs/results/NAME.json`` files."""
    (tmp_path / "docs" / "results").mkdir(parents=True)
    for name, result in (results if results is not None else {"r": {"x": 1.5, "rows": [{"a": 1}, {"a": 2}]}}).items():
        doc = {"command": f"sgatwalk {name}", "result": result, "stamp": STAMP}
        (tmp_path / "docs" / "results" / f"{name}.json").write_text(json.dumps(doc))
    for rel, text in pages.items():
        path = tmp_path / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return str(tmp_path)


def test_the_repository_docs_are_current_and_consistent():
    problems = docs.run(docs.ROOT, check=True)
    assert problems == [], "\n".join(problems) + "\n(run python -m tools.docs, then fix what is left)"


def test_render_fills_values_tables_and_stamps(tmp_path):
    root = _repo(tmp_path, {"README.md": (
        "x is <!-- value r:x:.2f --><!-- /value -->.\n\n"
        "<!-- result r:rows\n| a |\n|---|\n| {a:.1f} |\n-->\n<!-- /result -->\n")})
    assert docs.run(root) == []
    text = (tmp_path / "README.md").read_text()
    assert "x is <!-- value r:x:.2f -->1.50<!-- /value -->." in text
    assert "| 1.0 |\n| 2.0 |" in text
    assert "*`sgatwalk r` · Test CPU, 2 cores · commit 0123456 · 2026-01-01*" in text
    assert docs.run(root, check=True) == []  # rendered: nothing stale


def test_a_stamp_shows_the_command_without_its_output_and_run_directory_names():
    assert docs._shown_command("sgatwalk fidelity --out runs/fid-r28 --seed 3") == "sgatwalk fidelity --seed 3"
    assert docs._shown_command("python b.py --run runs/fid-r25 --walks 4") == "python b.py --run runs/RUN --walks 4"
    shown = docs._shown_command("sgatwalk fidelity --params runs/t-r27/a.json runs/t-r27/b.json runs/x/c.json")
    assert shown == "sgatwalk fidelity --params runs/RUN1/a.json runs/RUN1/b.json runs/RUN2/c.json"
    assert docs._shown_command(None) == "(command not recorded)"


def test_a_stale_block_is_detected_and_check_changes_nothing(tmp_path):
    page = "x is <!-- value r:x:.2f -->9.99<!-- /value -->.\n"
    root = _repo(tmp_path, {"README.md": page})
    problems = docs.run(root, check=True)
    assert any("stale" in p and "value r:x" in p for p in problems), problems
    assert (tmp_path / "README.md").read_text() == page


def test_a_missing_key_or_file_is_detected(tmp_path):
    root = _repo(tmp_path, {"README.md": "<!-- value r:nope --><!-- /value --> <!-- value gone:x --><!-- /value -->\n"})
    problems = docs.run(root, check=True)
    assert any("nope" in p for p in problems), problems
    assert any("docs/results/gone.json" in p for p in problems), problems


def test_a_broken_link_or_anchor_is_detected(tmp_path):
    root = _repo(tmp_path, {
        "README.md": V + " [a](docs/a.md#there) [b](docs/a.md#nowhere) [c](docs/none.md)\n",
        "docs/a.md": "# A\n\n## There\n"})
    problems = docs.run(root, check=True)
    assert any("docs/a.md#nowhere" in p for p in problems), problems
    assert any("docs/none.md" in p for p in problems), problems
    assert not any("#there" in p for p in problems), problems


@pytest.mark.parametrize("word", ["round", "Rounds", "session", "issue", "issues", "the faster kind"])
def test_a_process_word_in_prose_is_detected(tmp_path, word):
    root = _repo(tmp_path, {"README.md": f"{V} Made in the last {word}.\n"})
    assert any("the project speaks of itself" in p for p in docs.run(root, check=True))


def test_code_is_exempt_from_the_process_words(tmp_path):
    page = (f"{V} `--rounds 2` and `round(x)`\n\n"
            "```text\nscreen/refit rounds, see the issue\n```\n")
    root = _repo(tmp_path, {"README.md": page})
    assert docs.run(root, check=True) == []


def test_the_readme_line_limit(tmp_path):
    ok = V + "\n" + "line\n" * (docs.README_MAX_LINES - 1)
    root = _repo(tmp_path, {"README.md": ok})
    assert docs.run(root, check=True) == []
    (tmp_path / "README.md").write_text(ok + "one too many\n")
    assert any("README.md:" in p and "lines" in p for p in docs.run(root, check=True))


def test_an_unused_result_and_a_private_path_are_detected(tmp_path):
    root = _repo(tmp_path, {"README.md": V + " see ../shared/DESIGN.md\n"},
                 results={"r": {"x": 1.5}, "unused": {"x": 2}})
    problems = docs.run(root, check=True)
    assert any("docs/results/unused.json" in p for p in problems), problems
    assert any("../shared" in p for p in problems), problems
