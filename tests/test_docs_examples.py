"""Every code example of the manual and of README.md runs as written.

Each page (README.md, and every Markdown page of docs/ but the generated API reference) runs
in a directory of its own: a ```python block whose first line is ``# NAME.py`` (a comment
naming a file, as a system file starts) is written to that file, and every other ```python
block of the page is executed in order in one namespace, from that directory, as a reader
would paste them into one session. A block that cannot run here says so just before it, in a
comment the rendered page does not show: ``<!-- example: not run: the reason -->`` (a ROS
client that needs a running node, a fragment of a file shown above). Nothing else is skipped.
"""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: a fenced Python block, and the comment that may precede it
_BLOCK = re.compile(r"(?:<!--\s*example:\s*(?P<skip>not run:[^>]*?)\s*-->\s*\n)?"
                    r"```python\n(?P<code>.*?)```", re.S)
_FILE = re.compile(r"#\s*(?P<name>[\w-]+\.py)\b")


def pages() -> list[Path]:
    found = [ROOT / "README.md"]
    for path in sorted((ROOT / "docs").rglob("*.md")):
        rel = path.relative_to(ROOT / "docs").parts
        if rel[0] in ("_build",) or "generated" in rel:
            continue
        found.append(path)
    return found


def examples(path: Path) -> list[tuple[str, str | None, str]]:
    """(kind, file name or skip reason, code) of each block: kind "file", "run" or "skip"."""
    out: list[tuple[str, str | None, str]] = []
    for m in _BLOCK.finditer(path.read_text()):
        code = m["code"]
        first = code.splitlines()[0] if code.strip() else ""
        name = _FILE.match(first)
        if name:
            out.append(("file", name["name"], code))
        elif m["skip"]:
            out.append(("skip", m["skip"], code))
        else:
            out.append(("run", None, code))
    return out


def _id(path: Path) -> str:
    return str(path.relative_to(ROOT))


RUNNABLE = [p for p in pages() if any(kind == "run" for kind, _, _ in examples(p))]


@pytest.mark.parametrize("page", RUNNABLE, ids=_id)
def test_the_examples_of_a_page_run(page, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("BIPED_OPT_AOT", "0")
    namespace: dict = {"__name__": "__example__"}
    for k, (kind, name, code) in enumerate(examples(page)):
        if kind == "file":
            (tmp_path / str(name)).write_text(code)
        elif kind == "run":
            with contextlib.redirect_stdout(io.StringIO()):
                exec(compile(code, f"{_id(page)}, example {k + 1}", "exec"),  # noqa: S102
                     namespace)


def test_every_skipped_example_says_why():
    """A skip marker names its reason in words, and is never the only example of a page
    with runnable code (a page whose examples all stopped running would otherwise pass)."""
    for page in pages():
        for kind, reason, _code in examples(page):
            if kind == "skip":
                assert reason and len(reason.split()) >= 4, (page, reason)


def test_the_runner_reads_files_runs_and_skips(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("text\n```python\n# a.py: a file\nX = 1\n```\n"
                    "<!-- example: not run: needs a running optimiser node -->\n"
                    "```python\nraise SystemExit\n```\n```python\nprint(1)\n```\n")
    assert [(kind, name) for kind, name, _ in examples(page)] == [
        ("file", "a.py"), ("skip", "not run: needs a running optimiser node"), ("run", None)]
