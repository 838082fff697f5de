"""Render the docs from saved results, and check them.

    python -m tools.docs            # rewrite README.md and docs/**/*.md in place
    python -m tools.docs --check    # list every problem and exit 1; change nothing

Every number a page shows comes from a saved result, ``docs/results/NAME.json`` (``python -m
tools.results save NAME -- COMMAND`` writes ``{"command", "result", "stamp"}``), through one of three
markers (Markdown comments, invisible on GitHub):

* a result block, ``<!-- result NAME[:PATH] -->`` ... ``<!-- /result -->``: the text between the two
  is the value at PATH inside the file's ``"result"`` (default: its ``table`` if it has one, else its
  ``text``): a string as a fenced text block, a list of objects (or an object of objects) as a
  Markdown table, anything else as JSON; then one italic line, the stamp: the command, the CPU model
  and cores, the commit and the date. A table's columns can be chosen: the marker's lines after the
  first, up to ``-->``, are the table's header lines and, last, a row template whose ``{PATH[:FORMAT]}``
  fields are read from each row (``{_key}``: the row's key in an object of objects);
* an inline value, ``<!-- value NAME:PATH[:FORMAT] -->`` ... ``<!-- /value -->`` (FORMAT a Python
  format spec such as ``.2f``, ``+.1f`` or ``.0%``; default ``g``);
* an inline stamp, ``<!-- stamp NAME -->`` ... ``<!-- /stamp -->``: the stamp line of a result block,
  for a table put together from values of one file.

PATH is keys and list indices joined by dots (``rows.2.fitness_mean``); ``rows[method=sgat]`` picks the
first object of a list whose ``method`` is ``sgat`` (``[a=x,b=y]``: both), ``rows[0:11:2]`` slices a list, and a key that
holds dots or colons is written in double quotes (``worlds."real:mean=1".summary``). Markers inside
code (fenced blocks, inline code) are left alone.

Results saved before stamps existed carry ``"machine": {"cpus", ...}`` and no stamp: their line says
"CPU model not recorded", with the commit and date of the git commit that added the file's present
content (found by its blob hash, so that a renamed file keeps its commit; where git or the history is
missing, e.g. in a shallow clone, the commit and date already on the page are kept).

``--check`` fails on: a page whose rendered form differs from the file; a marker that names a missing
JSON file or key; a relative link to a missing file, or to an ``#anchor`` the target page does not
give (GitHub's heading slugs and ``<a id>`` tags); the words "round(s)", "session", "issue(s)" and the
phrases "faster kind" / "slower kind" outside code (the project speaks of itself, not of how it was
made); a JSON file under ``docs/results/`` that no page names; a README of more than
:data:`README_MAX_LINES` lines; a mention of a path outside the public repository (``../shared``).
``tests/test_docs.py`` runs it. This tool imports nothing of the project (``tests/test_architecture.py``).
"""

from __future__ import annotations

import argparse
import functools
import hashlib
import json
import math
import os
import re
import subprocess
import sys
from dataclasses import dataclass, field

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
#: The longest the README may be: a front door, not the documentation.
README_MAX_LINES = 300
#: Words a page may not use outside code (whole words, any case), and phrases.
PROCESS_WORDS = ("round", "rounds", "session", "issue", "issues")
PROCESS_PHRASES = ("faster kind", "slower kind")
#: Paths that are not part of the public repository: no page may name them.
PRIVATE_PATHS = ("../shared", "/work/shared")

_FENCE = re.compile(r"^\s*(```|~~~)")
_HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*#*\s*$")
_ANCHOR_TAG = re.compile(r'<a\s+(?:id|name)="([^"]+)"')
_LINK = re.compile(r"\]\(([^)\s]+)\)")
_INLINE_CODE = re.compile(r"(`+)(?:(?!\1).)+?\1")
_MARKER = re.compile(
    r"<!-- result (?P<rhead>(?:(?!<!--).)*?)-->(?P<rbody>(?:(?!<!-- result ).)*?)<!-- /result -->"
    r"|<!-- value (?P<vspec>[^\n]*?) -->(?P<vbody>[^\n]*?)<!-- /value -->"
    r"|<!-- stamp (?P<sname>[^\n]*?) -->(?P<sbody>[^\n]*?)<!-- /stamp -->", re.S)
_FIELD = re.compile(r"\{([^{}]+)\}")
_WORDS = re.compile(r"\b(" + "|".join(PROCESS_WORDS) + r")\b", re.I)
_STAMP_TAIL = re.compile(r"(commit [^*]*?)\*\s*$")


# ---------------------------------------------------------------------------------------------- paths


class SpecError(ValueError):
    """A marker that cannot be read, or that names a file or key that is not there."""


def split_spec(text: str) -> tuple[list[tuple], str | None]:
    """``PATH[:FORMAT]`` -> (steps, format or None). A step is ``("key", k)``, ``("index", i)``,
    ``("select", ((k, v), ...))`` or ``("slice", slice)``.

    Raises:
        SpecError: an unclosed quote or bracket, or a bracket that is none of ``[i]``, ``[k=v]``, ``[a:b:c]``.
    """
    steps: list[tuple] = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if c == '"':
            j = text.find('"', i + 1)
            if j < 0:
                raise SpecError(f"unclosed quote in {text!r}")
            steps.append(("key", text[i + 1:j]))
            i = j + 1
        elif c == "[":
            j = text.find("]", i)
            if j < 0:
                raise SpecError(f"unclosed [ in {text!r}")
            steps.append(_bracket(text[i + 1:j], text))
            i = j + 1
        elif c == ".":
            i += 1
        elif c == ":":
            return steps, text[i + 1:]
        else:
            tok = re.match(r'[^.\[\]":]+', text[i:]).group(0)
            steps.append(("index", int(tok)) if re.fullmatch(r"-?\d+", tok) else ("key", tok.strip()))
            i += len(tok)
    return steps, None


def _bracket(inner: str, whole: str) -> tuple:
    if "=" in inner:
        conds = tuple((k.strip(), v.strip()) for k, _, v in (c.partition("=") for c in inner.split(",")))
        if any(not k for k, _ in conds):
            raise SpecError(f"bad [{inner}] in {whole!r}")
        return ("select", conds)
    if ":" in inner:
        try:
            parts = [int(p) if p.strip() else None for p in inner.split(":")]
        except ValueError:
            raise SpecError(f"bad slice [{inner}] in {whole!r}") from None
        return ("slice", slice(*parts[:3]))
    if re.fullmatch(r"\s*-?\d+\s*", inner):
        return ("index", int(inner))
    raise SpecError(f"bad [{inner}] in {whole!r}: use [index], [key=value] or [start:stop:step]")


def _same(x, v: str) -> bool:
    if isinstance(x, bool):
        return str(x).lower() == v.lower() or str(int(x)) == v
    if isinstance(x, (int, float)):
        try:
            return float(v) == x
        except ValueError:
            return False
    return str(x) == v


def resolve(value, steps: list[tuple], what: str = "value"):
    """The value ``steps`` lead to from ``value``.

    Raises:
        SpecError: a key, index or selection that is not there (naming where it stopped).
    """
    walked = []
    for st in steps:
        kind = st[0]
        try:
            if kind == "key":
                if not isinstance(value, dict) or st[1] not in value:
                    raise KeyError
                value = value[st[1]]
            elif kind == "index":
                if isinstance(value, dict) and str(st[1]) in value:  # keys such as "8" in by_episodes
                    value = value[str(st[1])]
                elif isinstance(value, list):
                    value = value[st[1]]
                else:
                    raise KeyError
            elif kind == "select":
                if not isinstance(value, list):
                    raise KeyError
                value = next(x for x in value if isinstance(x, dict)
                             and all(k in x and _same(x[k], v) for k, v in st[1]))
            else:
                if not isinstance(value, list):
                    raise KeyError
                value = value[st[1]]
        except (KeyError, IndexError, StopIteration, TypeError):
            shown = ".".join(walked) or "(top)"
            raise SpecError(f"{what}: nothing at {_step_text(st)} after {shown}") from None
        walked.append(_step_text(st))
    return value


def _step_text(st: tuple) -> str:
    if st[0] == "key":
        return st[1] if re.fullmatch(r"[\w-]+", st[1]) else f'"{st[1]}"'
    if st[0] == "index":
        return str(st[1])
    if st[0] == "select":
        return "[" + ",".join(f"{k}={v}" for k, v in st[1]) + "]"
    s = st[1]
    return "[" + ":".join("" if x is None else str(x) for x in (s.start, s.stop, s.step)) + "]"


def format_value(v, spec: str | None = None) -> str:
    """A value as text: numbers with ``spec`` (default ``g``), None and non-finite numbers as "–",
    lists element by element in brackets, strings as they are (or formatted when a spec is given)."""
    spec = spec if spec not in (None, "") else "g"
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, (int, float)):
        try:
            return format(v, spec)
        except ValueError as e:
            raise SpecError(f"format {spec!r} does not apply to {v!r}: {e}") from None
    if isinstance(v, str):
        return v if spec == "g" else format(v, spec)
    if isinstance(v, list):
        return "[" + ", ".join(format_value(x, spec) for x in v) + "]"
    return json.dumps(v, ensure_ascii=False)


# ------------------------------------------------------------------------------------------- results


@dataclass
class Results:
    """The saved results of one repository (``docs/results/``), loaded once each."""

    root: str
    _cache: dict = field(default_factory=dict)

    @property
    def folder(self) -> str:
        return os.path.join(self.root, "docs", "results")

    def load(self, name: str) -> dict:
        """``docs/results/NAME.json`` as a dict.

        Raises:
            SpecError: no such file, or not a JSON object with a ``result``.
        """
        if name not in self._cache:
            if not re.fullmatch(r"[\w.-]+(/[\w.-]+)*", name):
                raise SpecError(f"bad result name {name!r}")
            path = os.path.join(self.folder, name + ".json")
            if not os.path.isfile(path):
                raise SpecError(f"no file docs/results/{name}.json")
            try:
                with open(path, "rb") as f:
                    raw = f.read()
                doc = json.loads(raw)
            except (OSError, json.JSONDecodeError) as e:
                raise SpecError(f"docs/results/{name}.json is not JSON: {e}") from None
            if not isinstance(doc, dict) or "result" not in doc:
                raise SpecError(f"docs/results/{name}.json has no \"result\"")
            self._cache[name] = (doc, _blob_hash(raw))
        return self._cache[name][0]

    def stamp(self, name: str) -> str | None:
        """The stamp line of a result: the command, CPU model and cores, commit and date. None: a
        result without a stamp whose commit git cannot tell (keep what the page says)."""
        doc = self.load(name)
        cmd = _shown_command(doc.get("command"))
        st = doc.get("stamp")
        if isinstance(st, dict):
            cores = st.get("cores")
            cpu = f"{st.get('cpu') or 'CPU model not recorded'}" + (f", {cores} cores" if cores else "")
            commit = str(st.get("commit") or "not recorded")[:7]
            if st.get("dirty"):
                commit += " (with uncommitted changes)"
            return f"*`{cmd}` · {cpu} · commit {commit} · {st.get('date') or 'date not recorded'}*"
        cores = (doc.get("machine") or {}).get("cpus")
        cpu = "CPU model not recorded" + (f", {cores} cores" if cores else "")
        prov = _provenance(self.root).get(self._cache[name][1]) if _provenance(self.root) is not None else None
        head = f"*`{cmd}` · {cpu} · "
        if prov is None:
            return None if _provenance(self.root) is None else head + "commit not recorded*"
        return head + f"commit {prov[0]} · {prov[1]}*"

    def legacy_head(self, name: str) -> str:
        """The part of a stamp line before the commit (for keeping a page's commit where git cannot tell)."""
        doc = self.load(name)
        cores = (doc.get("machine") or {}).get("cpus")
        return (f"*`{_shown_command(doc.get('command'))}` · CPU model not recorded"
                + (f", {cores} cores" if cores else "") + " · ")


#: A run directory under ``runs/`` named in a command (its name, group 1).
_RUN_DIR = re.compile(r"\bruns/([^/\s]+)")


def _shown_command(cmd: str | None) -> str:
    """A result's command as a stamp shows it: without ``--out DIR`` (where its files went, not a setting
    of the run), and with the run directories it reads under ``runs/`` shown as ``runs/RUN`` (``RUN1``,
    ``RUN2``, ... when there are several): a directory's name says when it was made, not what it holds."""
    if not cmd:
        return "(command not recorded)"
    cmd = re.sub(r"\s--out(?:=|\s+)\S+", "", cmd)
    names = list(dict.fromkeys(_RUN_DIR.findall(cmd)))
    tag = {n: "RUN" if len(names) == 1 else f"RUN{i + 1}" for i, n in enumerate(names)}
    return _RUN_DIR.sub(lambda m: f"runs/{tag[m.group(1)]}", cmd)


def _blob_hash(data: bytes) -> str:
    return hashlib.sha1(b"blob %d\0" % len(data) + data).hexdigest()


@functools.lru_cache(maxsize=None)
def _provenance(root: str) -> dict[str, tuple[str, str]] | None:
    """Blob hash -> (abbreviated commit, date) of the oldest commit that added that content under
    ``docs/results/`` (one ``git log`` over the folder's history). None: no git, not a repository or a
    shallow clone (whose oldest commit would claim every file)."""
    def git(*args):
        return subprocess.run(["git", *args], cwd=root, capture_output=True, text=True, timeout=120)
    try:
        sh = git("rev-parse", "--is-shallow-repository")
        if sh.returncode != 0 or sh.stdout.strip() != "false":
            return None
        out = git("log", "--format=%x00%h %cs", "--raw", "--no-abbrev", "--no-renames", "--", "docs/results")
    except (OSError, subprocess.SubprocessError):
        return None
    if out.returncode != 0:
        return None
    blobs: dict[str, tuple[str, str]] = {}
    commit = None
    for line in out.stdout.splitlines():
        if line.startswith("\0"):
            h, _, date = line[1:].partition(" ")
            commit = (h[:7], date)
        elif line.startswith(":") and commit:
            fields = line.split("\t")[0].split()
            if len(fields) >= 4 and set(fields[3]) != {"0"}:
                blobs[fields[3]] = commit  # newest first: the oldest commit that added it wins
    return blobs


# ------------------------------------------------------------------------------------------ rendering


def _table(value, header: list[str], row_tpl: str | None) -> str:
    """A list of objects, or an object of objects, as Markdown table lines."""
    if isinstance(value, dict):
        rows = [(k, v) for k, v in value.items()]
    else:
        rows = [(i, v) for i, v in enumerate(value)]
    if row_tpl is None:
        cols: list[str] = []
        for _, r in rows:
            cols += [c for c in r if c not in cols]
        keyed = isinstance(value, dict)
        head = ([""] if keyed else []) + cols
        lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for k, r in rows:
            cells = ([str(k)] if keyed else []) + [_cell(format_value(r.get(c), ".4g")) for c in cols]
            lines.append("| " + " | ".join(cells) + " |")
        return "\n".join(lines)
    out = list(header)
    for k, r in rows:
        def fill(m, r=r, k=k):
            inner = m.group(1)
            if inner.strip() == "_key":
                return _cell(str(k))
            steps, spec = split_spec(inner)
            return _cell(format_value(resolve(r, steps, f"row {k}"), spec))
        out.append(_FIELD.sub(fill, row_tpl))
    return "\n".join(out)


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def render_result(results: Results, head: str, old_body: str) -> str:
    """The body of a result block (between its markers) for the marker text ``head``.

    Raises:
        SpecError: a bad marker, a missing file or key.
    """
    lines = [ln.strip() for ln in head.strip().splitlines() if ln.strip()]
    if not lines:
        raise SpecError("result marker without a name")
    name, _, path = lines[0].partition(":")
    name = name.strip()
    doc = results.load(name)
    res = doc["result"]
    if path.strip():
        steps, spec = split_spec(path.strip())
        value = resolve(res, steps, f"result {name}")
    else:
        spec = None
        if isinstance(res, dict) and "table" in res:
            value = res["table"]
        elif isinstance(res, dict) and "text" in res:
            value = res["text"]
        else:
            raise SpecError(f"result {name}: no \"table\" or \"text\"; name a key (NAME:KEY.PATH)")
    tpl = lines[1:]
    if isinstance(value, str) and not tpl:
        content = "```text\n" + value.rstrip("\n") + "\n```"
    elif isinstance(value, (list, dict)) and value and all(isinstance(v, dict) for v in
                                                           (value.values() if isinstance(value, dict) else value)):
        content = _table(value, tpl[:-1], tpl[-1] if tpl else None)
    elif tpl:
        raise SpecError(f"result {name}: a row template needs a list of objects or an object of objects")
    else:
        content = "```text\n" + (format_value(value, spec) if not isinstance(value, (dict, list))
                                 else json.dumps(value, indent=1, ensure_ascii=False)) + "\n```"
    stamp = results.stamp(name)
    if stamp is None:
        stamp = _kept_stamp(results.legacy_head(name), old_body)
    return "\n" + content + "\n\n" + stamp + "\n"


def _kept_stamp(head: str, old: str) -> str:
    """A legacy stamp whose commit git cannot tell: the commit and date the page already shows."""
    for line in reversed(old.strip().splitlines()):
        m = _STAMP_TAIL.search(line)
        if m:
            return head + m.group(1) + "*"
    return head + "commit not recorded*"


def code_spans(text: str) -> list[tuple[int, int]]:
    """(start, end) of every fenced code block and inline code span of a Markdown text."""
    spans, pos, fence_start = [], 0, None
    for line in text.splitlines(keepends=True):
        if _FENCE.match(line):
            if fence_start is None:
                fence_start = pos
            else:
                spans.append((fence_start, pos + len(line)))
                fence_start = None
        elif fence_start is None:
            spans += [(pos + m.start(), pos + m.end()) for m in _INLINE_CODE.finditer(line)]
        pos += len(line)
    if fence_start is not None:
        spans.append((fence_start, len(text)))
    return spans


def _inside(pos: int, spans: list[tuple[int, int]]) -> bool:
    return any(a <= pos < b for a, b in spans)


@dataclass
class Page:
    """A page rendered: its new text, the blocks whose text changed and the problems found."""

    path: str
    text: str
    new: str
    stale: list[str]
    problems: list[str]


def render(text: str, results: Results, where: str = "page") -> tuple[str, list[str], list[str]]:
    """Render every marker of a Markdown text; returns (new text, stale blocks, problems). A marker
    that cannot be rendered stays as it was and is a problem."""
    spans = _outer_code_spans(text)
    stale, problems = [], []

    def line_of(pos):
        return text.count("\n", 0, pos) + 1

    def sub(m):
        if _inside(m.start(), spans):
            return m.group(0)
        at = f"{where}:{line_of(m.start())}"
        try:
            if m.group("rhead") is not None:
                head, body = m.group("rhead"), m.group("rbody")
                new = render_result(results, head, body)
                label = "result " + head.strip().splitlines()[0].strip()
                out = f"<!-- result {head}-->{new}<!-- /result -->"
            elif m.group("vspec") is not None:
                spec, body = m.group("vspec"), m.group("vbody")
                name, _, rest = spec.partition(":")
                steps, fmt = split_spec(rest)
                if not steps:
                    raise SpecError(f"value {spec!r}: name a key (NAME:KEY.PATH[:FORMAT])")
                doc = results.load(name.strip())
                new = format_value(resolve(doc["result"], steps, f"value {name.strip()}"), fmt)
                label = "value " + spec
                out = f"<!-- value {spec} -->{new}<!-- /value -->"
            else:
                name, body = m.group("sname").strip(), m.group("sbody")
                new = results.stamp(name)
                if new is None:
                    new = _kept_stamp(results.legacy_head(name), body)
                label = "stamp " + name
                out = f"<!-- stamp {m.group('sname')} -->{new}<!-- /stamp -->"
        except SpecError as e:
            problems.append(f"{at}: {e}")
            return m.group(0)
        if new != body:
            stale.append(f"{at}: {label}")
        return out

    return _MARKER.sub(sub, text), stale, problems


def _outer_code_spans(text: str) -> list[tuple[int, int]]:
    """Code spans that are not inside a result block's body (whose fences are the block's own)."""
    blocks = [(m.start("rbody"), m.end("rbody")) for m in _MARKER.finditer(text) if m.group("rhead") is not None]
    return [s for s in code_spans(text) if not any(a <= s[0] < b for a, b in blocks)]


# ------------------------------------------------------------------------------------------- checking


def github_slug(heading: str) -> str:
    """The anchor GitHub gives a heading: lower case, every character but letters, digits, ``-``, ``_``
    and spaces dropped (backticks, punctuation, dashes such as "—"), spaces turned into ``-``."""
    s = heading.strip().lower()
    s = "".join(c for c in s if c.isalnum() or c in "-_ ")
    return s.replace(" ", "-")


def anchors(text: str) -> set[str]:
    """Every anchor of a Markdown text: heading slugs (repeats get ``-1``, ``-2``, ... as on GitHub) and
    ``<a id="...">`` tags; headings inside code fences do not count."""
    out, seen, fenced = set(), {}, False
    for line in text.splitlines():
        if _FENCE.match(line):
            fenced = not fenced
            continue
        if fenced:
            continue
        out.update(_ANCHOR_TAG.findall(line))
        m = _HEADING.match(line)
        if m:
            slug = github_slug(m.group(2))
            n = seen.get(slug, 0)
            seen[slug] = n + 1
            out.add(slug if n == 0 else f"{slug}-{n}")
    return out


def _external(target: str) -> bool:
    return "://" in target or target.startswith("mailto:")


def broken_links(text: str, folder: str) -> list[str]:
    """Relative links of a Markdown text (outside code) that lead nowhere: ``#anchor`` without that
    anchor in the text, ``path`` / ``path#anchor`` without the file (relative to ``folder``, the page's
    own), and ``page.md#anchor`` where that page gives no such anchor. Returns the targets, in order,
    once each."""
    have, other, bad = anchors(text), {}, []
    spans = code_spans(text)
    for m in _LINK.finditer(text):
        target = m.group(1)
        if _inside(m.start(), spans) or _external(target) or target in bad:
            continue
        path, _, frag = target.partition("#")
        full = os.path.normpath(os.path.join(folder, path))
        if (not path and frag not in have) or (path and not os.path.exists(full)):
            bad.append(target)
        elif path and frag and path.endswith(".md"):
            if full not in other:
                with open(full, encoding="utf-8") as f:
                    other[full] = anchors(f.read())
            if frag not in other[full]:
                bad.append(target)
    return bad


def process_words(text: str) -> list[tuple[int, str]]:
    """(line, word) of every process word or phrase outside code."""
    spans = code_spans(text)
    found = []
    for m in _WORDS.finditer(text):
        if not _inside(m.start(), spans):
            found.append((text.count("\n", 0, m.start()) + 1, m.group(0)))
    low = text.lower()
    for phrase in PROCESS_PHRASES:
        for m in re.finditer(re.escape(phrase), low):
            if not _inside(m.start(), spans):
                found.append((text.count("\n", 0, m.start()) + 1, text[m.start():m.end()]))
    return sorted(found)


def pages(root: str) -> list[str]:
    """README.md and every Markdown page under docs/, relative to ``root``, sorted."""
    out = ["README.md"] if os.path.isfile(os.path.join(root, "README.md")) else []
    for dirpath, dirnames, filenames in os.walk(os.path.join(root, "docs")):
        dirnames.sort()
        out += sorted(os.path.relpath(os.path.join(dirpath, f), root) for f in filenames if f.endswith(".md"))
    return out


def result_files(root: str) -> list[str]:
    """Every JSON file under docs/results/, relative to that folder (``NAME.json``, ``sub/NAME.json``)."""
    folder = os.path.join(root, "docs", "results")
    out = []
    for dirpath, dirnames, filenames in os.walk(folder):
        dirnames.sort()
        out += sorted(os.path.relpath(os.path.join(dirpath, f), folder) for f in filenames if f.endswith(".json"))
    return out


def _named_results(text: str) -> set[str]:
    """The result files a page names: through its markers, or as a path ending ``results/NAME.json``."""
    names = set()
    for m in _MARKER.finditer(text):
        if m.group("rhead") is not None:
            names.add(m.group("rhead").strip().splitlines()[0].partition(":")[0].strip() + ".json")
        elif m.group("vspec") is not None:
            names.add(m.group("vspec").partition(":")[0].strip() + ".json")
        else:
            names.add(m.group("sname").strip() + ".json")
    names.update(re.findall(r"results/([\w./-]+?\.json)", text))
    return names


def run(root: str = ROOT, check: bool = False) -> list[str]:
    """Render every page (``check``: only compare) and check them all; returns the problems, one line
    each (an empty list: all is well)."""
    results = Results(root)
    problems: list[str] = []
    named: set[str] = set()
    for rel in pages(root):
        path = os.path.join(root, rel)
        with open(path, encoding="utf-8") as f:
            text = f.read()
        new, stale, errs = render(text, results, rel)
        problems += errs
        if check:
            problems += [f"{s} is stale (run python -m tools.docs)" for s in stale]
        elif new != text:
            tmp = path + ".tmp"
            with open(tmp, "w", encoding="utf-8") as f:
                f.write(new)
            os.replace(tmp, path)
        named |= _named_results(new)
        problems += [f"{rel}: link to {t} leads nowhere" for t in broken_links(new, os.path.dirname(path))]
        problems += [f"{rel}:{ln}: the word {w!r} (the project speaks of itself, not of how it was made)"
                     for ln, w in process_words(new)]
        for p in PRIVATE_PATHS:
            if p in new:
                problems.append(f"{rel}: names {p!r}, which is not part of the public repository")
        if rel == "README.md":
            n = len(new.splitlines())
            if n > README_MAX_LINES:
                problems.append(f"README.md: {n} lines, over {README_MAX_LINES}")
    problems += [f"docs/results/{f}: no page names it (use it on a page, or delete it: git keeps it)"
                 for f in result_files(root) if f not in named]
    return problems


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tools.docs", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--check", action="store_true", help="change nothing; exit 1 listing every problem")
    ap.add_argument("--root", default=ROOT, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    problems = run(a.root, check=a.check)
    for p in problems:
        print(p, file=sys.stderr)
    if problems:
        print(f"{len(problems)} problem(s)", file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
