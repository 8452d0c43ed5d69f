"""The specification the code cites is the repository's own: docs/MODEL.md, docs/SYSTEMS.md,
docs/ROS.md and docs/MCAP.md.

Every citation of them in the package, the tests, the benchmarks, README and docs/ itself
(``MODEL.md Sec. 6``, ``SYSTEMS.md Secs. 2-3``, ``MODEL.md R5``, ``SYSTEMS.md, "Events"``,
``ROS.md Sec. 2``, ``MCAP.md: "What ROS 2 tools need"``, also when a comment wraps it over two
lines) must name a section (a numbered ``## N.`` heading, or a
heading's title) or a reference row that the cited file holds, and must point at docs/, not at
a copy elsewhere. The citations are read from the sources as text, so removing or renumbering a
section that something cites fails here, naming the citing file and line.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
#: the specification files, under docs/
SPECS = ("MODEL.md", "SYSTEMS.md", "ROS.md", "MCAP.md")
#: where citations are looked for (this file is left out: it quotes citations to test the parser)
SCANNED = ("biped_opt", "tests", "bench", "launch", "config", "docs", "README.md")
SUFFIXES = {".py", ".md", ".yaml", ".yml", ".txt", ".cfg", ".toml", ".msg", ".srv", ".action"}
#: specification files cited by name that the repository does not hold yet; the list may only
#: shrink (a test below fails when one of them is no longer cited)
NOT_YET_IN_DOCS: set[str] = set()

# between two parts of a citation: blanks, or a line break into a comment (``#``, ``#:``)
_GAP = r"(?:[ \t]*\n[ \t]*(?:#:?)?)?[ \t]*"
_FILE = re.compile(r"(?<![\w./-])(?P<path>/?(?:[\w.-]+/)*)(?P<name>[A-Z][A-Z0-9_]*\.md)\b")
# what may follow a spec's name: a markdown link target, then sections, rows and titles
_LINK = re.compile(r"\]\([^)\s]*\)")
_SECTIONS = re.compile(_GAP + r"Secs?\." + _GAP + r"(\d+)(?:" + _GAP + r"(-|and)" + _GAP
                       + r"(\d+))?")
_ROWS = re.compile(_GAP + r"(R\d+)(?:" + _GAP + r"[-/]" + _GAP + r"(R\d+))?\b")
_TITLE = re.compile(_GAP + r"\(?\"([^\"\n]+)\"\)?")
_SEPARATOR = re.compile(_GAP + r"[,:]")
_HEADING = re.compile(r"^#{2,}[ \t]+(?:(\d+)\.[ \t]+)?(.+?)[ \t]*$", re.MULTILINE)
_ROW = re.compile(r"^\|[ \t]*(R\d+)[ \t]*\|", re.MULTILINE)


@dataclass(frozen=True)
class Citation:
    where: str  # file:line
    path: str  # the directory part written before the name ("" or "docs/")
    spec: str  # MODEL.md, SYSTEMS.md
    sections: tuple[int, ...] = ()
    rows: tuple[str, ...] = ()
    titles: tuple[str, ...] = ()


@dataclass(frozen=True)
class Spec:
    sections: dict[int, str]  # number -> title
    titles: set[str]
    rows: set[str]


def _rows(first: str, last: str | None) -> tuple[str, ...]:
    if last is None:
        return (first,)
    lo, hi = int(first[1:]), int(last[1:])
    return tuple(f"R{k}" for k in range(lo, hi + 1))


def parse(text: str, where: str = "text") -> list[Citation]:
    """The citations of specification files in ``text``, with what each names after the file."""
    out = []
    read_to = 0  # the end of the last citation (its link target is not a citation of its own)
    for match in _FILE.finditer(text):
        if match.start() < read_to:
            continue
        pos = match.end()
        link = _LINK.match(text, pos)
        if link:
            pos = link.end()
        sections: list[int] = []
        rows: list[str] = []
        titles: list[str] = []
        while True:
            sep = _SEPARATOR.match(text, pos)
            at = sep.end() if sep else pos
            if m := _SECTIONS.match(text, at):
                lo, hi = int(m[1]), int(m[3] or m[1])
                sections.extend(range(lo, hi + 1) if m[2] == "-" and lo <= hi else
                                dict.fromkeys((lo, hi)))
            elif m := _ROWS.match(text, at):
                rows.extend(_rows(m[1], m[2]))
            elif m := _TITLE.match(text, at):
                titles.append(m[1])
            else:
                break
            pos = m.end()
        read_to = pos
        line = text.count("\n", 0, match.start()) + 1
        out.append(Citation(f"{where}:{line}", match["path"], match["name"], tuple(sections),
                            tuple(rows), tuple(titles)))
    return out


def read_spec(path: Path) -> Spec:
    """The numbered sections, every heading's title (also its part before a colon, so
    ``"Events"`` names ``## 5. Events: ...``) and the reference rows of a specification."""
    text = path.read_text()
    sections, titles = {}, set()
    for number, title in _HEADING.findall(text):
        if number:
            sections[int(number)] = title
        titles.add(title)
        titles.add(title.split(":")[0])
    return Spec(sections, titles, set(_ROW.findall(text)))


def _scanned_files() -> list[Path]:
    me = Path(__file__).resolve()
    files = []
    for name in SCANNED:
        top = ROOT / name
        candidates = [top] if top.is_file() else sorted(top.rglob("*")) if top.is_dir() else []
        for path in candidates:
            rel = path.relative_to(ROOT).parts
            if (path.is_file() and path.suffix in SUFFIXES and path.resolve() != me
                    and not any(p.startswith(".") or p == "__pycache__" for p in rel)):
                files.append(path)
    return files


def _citations() -> list[Citation]:
    out = []
    for path in _scanned_files():
        out += parse(path.read_text(errors="replace"), str(path.relative_to(ROOT)))
    return out


CITATIONS = _citations()


def unresolved(citations: list[Citation], specs: dict[str, Spec]) -> list[str]:
    """What each citation names that its specification does not hold, one line each."""
    problems = []
    for c in citations:
        spec = specs.get(c.spec)
        if spec is None:
            continue
        for number in c.sections:
            if number not in spec.sections:
                problems.append(f"{c.where}: {c.spec} Sec. {number}: no such section "
                                f"(sections: {sorted(spec.sections)})")
        for row in c.rows:
            if row not in spec.rows:
                problems.append(f"{c.where}: {c.spec} {row}: no such reference row")
        for title in c.titles:
            if title not in spec.titles:
                problems.append(f"{c.where}: {c.spec}, \"{title}\": no heading with that title")
    return problems


def test_the_specification_is_in_docs() -> None:
    for name in SPECS:
        spec = read_spec(DOCS / name)
        assert spec.sections, f"{name} has no numbered section"
        # sections numbered 1..N without gaps: a citation's number means one thing
        assert sorted(spec.sections) == list(range(1, len(spec.sections) + 1)), name


def test_every_citation_names_a_section_the_docs_hold() -> None:
    specs = {name: read_spec(DOCS / name) for name in SPECS}
    cited = [c for c in CITATIONS if c.spec in SPECS]
    # the scan sees the citations at all: each spec is cited by section or title somewhere
    for name in SPECS:
        assert any(c.sections or c.titles for c in cited if c.spec == name), \
            f"no section of {name} cited"
    assert any(c.titles for c in cited) and any(c.rows for c in cited)
    problems = unresolved(cited, specs)
    assert not problems, "\n".join(problems)


def test_citations_point_at_the_repository_docs() -> None:
    """``MODEL.md`` bare (next to it in docs/, or by name from code) or ``docs/MODEL.md``;
    never a path to a copy outside docs/."""
    wrong = [f"{c.where}: {c.path}{c.spec}" for c in CITATIONS
             if c.spec in SPECS and c.path not in ("", "docs/")]
    assert not wrong, "\n".join(wrong)


def _exists(c: Citation) -> bool:
    """The cited file: by its path from the repository's root or from the citing file's folder,
    or, named bare, in docs/."""
    if c.path.startswith("/"):
        return False
    citing = (ROOT / c.where.rsplit(":", 1)[0]).parent
    return ((ROOT / c.path / c.spec).is_file() or (citing / c.path / c.spec).is_file()
            or (not c.path and (DOCS / c.spec).is_file()))


def test_every_cited_specification_file_exists() -> None:
    """A ``NAME.md`` cited anywhere is a file of the repository, except the ones listed in
    NOT_YET_IN_DOCS; and each of those is still cited (else drop it from the list)."""
    missing: dict[str, list[str]] = {}
    for c in CITATIONS:
        if not _exists(c):
            missing.setdefault(c.path + c.spec, []).append(c.where)
    unknown = {k: v for k, v in missing.items() if k not in NOT_YET_IN_DOCS}
    assert not unknown, "\n".join(f"{k}: cited at {', '.join(v)}" for k, v in unknown.items())
    assert set(missing) == NOT_YET_IN_DOCS, (
        f"no longer missing, remove from NOT_YET_IN_DOCS: {NOT_YET_IN_DOCS - set(missing)}")


@pytest.mark.parametrize("text, expected", [
    ("(MODEL.md Sec. 6)", [("", "MODEL.md", (6,), (), ())]),
    ("SYSTEMS.md Secs. 2-3.", [("", "SYSTEMS.md", (2, 3), (), ())]),
    ("SYSTEMS.md Secs. 1 and\n5: the", [("", "SYSTEMS.md", (1, 5), (), ())]),
    ("docs/SYSTEMS.md, \"Events\", states", [("docs/", "SYSTEMS.md", (), (), ("Events",))]),
    ("[docs/SYSTEMS.md](docs/SYSTEMS.md) (\"Events\")",
     [("docs/", "SYSTEMS.md", (), (), ("Events",))]),
    ("# flip (MODEL.md\n        # Sec. 3); the terminal", [("", "MODEL.md", (3,), (), ())]),
    ("#: MODEL.md Sec. 7, R3/R4: liftoff", [("", "MODEL.md", (7,), ("R3", "R4"), ())]),
    ("MODEL.md R1-R4; the table", [("", "MODEL.md", (), ("R1", "R2", "R3", "R4"), ())]),
    ("SYSTEMS.md, mirrored", [("", "SYSTEMS.md", (), (), ())]),
    ("SYSTEMS.md's (2, 1, 0.5)", [("", "SYSTEMS.md", (), (), ())]),
    ("from /elsewhere/SYSTEMS.md Sec. 2", [("/elsewhere/", "SYSTEMS.md", (2,), (), ())]),
])
def test_parse_reads_the_forms_the_sources_use(text: str, expected: list[tuple]) -> None:
    got = [(c.path, c.spec, c.sections, c.rows, c.titles) for c in parse(text)]
    assert got == expected


def test_a_missing_section_is_reported(tmp_path: Path) -> None:
    """The check itself can fail: a citation of a section the file lacks is named."""
    spec = tmp_path / "SYSTEMS.md"
    spec.write_text("# Title\n\n## 1. Framework rules\n\n## 2. Events\n")
    specs = {"SYSTEMS.md": read_spec(spec)}
    cited = parse("see SYSTEMS.md Secs. 1-3 and SYSTEMS.md, \"Events\"", "x.py")
    assert unresolved(cited, specs) == [
        "x.py:1: SYSTEMS.md Sec. 3: no such section (sections: [1, 2])"]
