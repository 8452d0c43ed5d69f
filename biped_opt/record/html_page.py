"""One self-contained HTML page of a report of recordings (:mod:`biped_opt.record.report`): what
a researcher looks at, or sends to a colleague, in one file.

The page holds, in this order:

- the provenance: biped_opt's version, when the page was made, and per recording its file, the
  system and maneuver, fixed inputs or optimal, its points and range, whether it was complete
  or recovered, and the metadata the recorder wrote (parameters, inputs, cost);
- the inputs: the fixed inputs of each fixed-input sweep, the decisions with their bounds and the
  cost of each optimal one;
- the nonsmooth table: per sweep, every point estimated at the recording's grid resolution with
  its bracket, quantity, kind and one-sided values (limits for a jump, slopes for a kink) with
  their error estimates and cause; where ``--refine`` located them again, that table too;
- every figure, embedded as a PNG data URL (the page loads nothing from anywhere).

Everything is escaped; nothing in it runs (no script). :func:`write_page` writes it beside the
figures as ``report.html``.
"""

from __future__ import annotations

import base64
import html
import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from biped_opt.version import __version__

#: (the report's types, biped_opt.record.report.Report and RecordedSweep, and
#: biped_opt.analysis.sampled.GridPoint: that module imports this one, so they are not named)
Report = Any
RecordedSweep = Any
GridPoint = Any

__all__ = ["PAGE_NAME", "page", "write_page"]

#: the page's file name in the report's directory
PAGE_NAME = "report.html"

_STYLE = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 72em; color: #222;
       padding: 0 1em; line-height: 1.4; }
h1 { font-size: 1.6em; } h2 { font-size: 1.25em; margin-top: 2em; border-bottom: 1px solid #ccc; }
table { border-collapse: collapse; margin: 0.8em 0; font-size: 0.92em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: left; vertical-align: top; }
td.num { text-align: right; font-variant-numeric: tabular-nums; font-family: monospace; }
th { background: #f3f3f3; }
.jump { color: #a00; font-weight: 600; } .kink { color: #06a; font-weight: 600; }
.note { color: #555; font-size: 0.9em; }
figure { margin: 1.2em 0; } figure img { max-width: 100%; border: 1px solid #ddd; }
pre { background: #f7f7f7; padding: 0.8em; overflow-x: auto; font-size: 0.85em; }
"""


def _e(value: object) -> str:
    return html.escape(str(value), quote=True)


def _num(value: float, digits: int = 9) -> str:
    return "" if not math.isfinite(value) else f"{value:.{digits}g}"


def _table(head: Sequence[str], rows: Sequence[Sequence[str]], numeric: Sequence[int] = ()
           ) -> str:
    """An HTML table; cells are HTML already (escape what comes from a recording)."""
    out = ["<table>", "<tr>" + "".join(f"<th>{_e(h)}</th>" for h in head) + "</tr>"]
    for row in rows:
        out.append("<tr>" + "".join(
            f"<td class=\"num\">{c}</td>" if k in numeric else f"<td>{c}</td>"
            for k, c in enumerate(row)) + "</tr>")
    out.append("</table>")
    return "\n".join(out)


def _provenance(report: Report) -> str:
    rows = []
    for s in report.sweeps:
        state = "complete" if s.complete else f"recovered: {s.note}"
        rows.append([_e(s.path.name), _e(s.system), _e(s.maneuver),
                     "optimal" if s.optimal else "fixed inputs", str(s.theta0.size),
                     f"[{_num(float(s.theta0[0]), 6)}, {_num(float(s.theta0[-1]), 6)}]",
                     _e(state)])
    meta = []
    for s in report.sweeps:
        pairs = "".join(f"<tr><th>{_e(k)}</th><td>{_e(v)}</td></tr>"
                        for k, v in sorted(s.metadata.items()) if not k.startswith("crc"))
        meta.append(f"<details><summary>{_e(s.path.name)}: the recorder's metadata</summary>"
                    f"<table>{pairs}</table></details>")
    return "\n".join([
        "<h2>Provenance</h2>",
        f"<p>biped_opt {_e(__version__)}; page made {_e(time.strftime('%Y-%m-%d %H:%M:%S %Z'))}"
        ".</p>",
        _table(["recording", "system", "maneuver", "sweep", "points", "range of s", "file"],
               rows, numeric=(4,)),
        *meta])


def _inputs(sweeps: Sequence[RecordedSweep]) -> str:
    rows = []
    for s in sweeps:
        if s.optimal:
            decisions = ", ".join(f"{d} in [{_num(lo, 6)}, {_num(hi, 6)}]"
                                  for d, (lo, hi) in s.decision_bounds)
            cost = s.metadata.get("cost", "") or s.metadata.get("problem", "")
            rows.append([_e(s.label), "optimal", _e(decisions), _e(cost)])
        else:
            given = ", ".join(f"{_num(float(u), 6)}" for u in s.inputs if math.isfinite(u))
            rows.append([_e(s.label), "fixed", _e(given or "none"), ""])
    return "\n".join(["<h2>Inputs</h2>",
                      _table(["sweep", "kind", "inputs / decisions (bounds)", "cost"], rows)])


def _points(points: Sequence[GridPoint]) -> str:
    rows = []
    for g in points:
        p = g.point
        err = g.limit_error if p.kind == "jump" else g.slope_error
        what = "limits" if p.kind == "jump" else "slopes"
        q = p.quantity if p.input is None else f"{p.quantity}:{p.input}"
        rows.append([_num(p.theta0), f"[{_num(p.bracket[0])}, {_num(p.bracket[1])}]",
                     _num(g.width, 3), _e(q), f"<span class=\"{_e(p.kind)}\">{_e(p.kind)}</span>",
                     _e(what), _num(p.left), _num(err[0], 2), _num(p.right), _num(err[1], 2),
                     _e(p.cause)])
    if not rows:
        return "<p class=\"note\">No jump or kink resolved at this grid resolution.</p>"
    return _table(["s", "bracket", "width", "quantity", "kind", "one-sided", "left", "±",
                   "right", "±", "cause"], rows, numeric=(0, 2, 6, 7, 8, 9))


def _nonsmooth(report: Report) -> str:
    out = ["<h2>Nonsmooth points</h2>",
           "<p class=\"note\">Estimates at the recording's grid resolution: each point lies in "
           "its recorded bracket; the one-sided values are limits (a jump) or slopes (a kink) "
           "of cubics through the four nearest recorded points on each side, ± the change "
           "from the quadratics through three. <code>biped-opt report --refine</code> locates "
           "them to 1e-10 with the core.</p>"]
    for s in report.sweeps:
        key = f"{s.kind}:{s.label}"
        out.append(f"<h3>{_e(s.label)} ({'optimal' if s.optimal else 'fixed inputs'})</h3>")
        out.append(_points(report.grid_points.get(key, ())))
    if report.refined:
        out.append("<h3>Refined with the core</h3>")
        rows = []
        for rep in report.refined:
            for p in rep.points:
                q = p.quantity if p.input is None else f"{p.quantity}:{p.input}"
                rows.append([_e(rep.subject), _num(p.theta0, 12), _e(q),
                             f"<span class=\"{_e(p.kind)}\">{_e(p.kind)}</span>",
                             _num(p.left), _num(p.right), _e(p.cause)])
        out.append(_table(["sweep", "s", "quantity", "kind", "left", "right", "cause"], rows,
                          numeric=(1, 4, 5)))
    out.append(f"<details><summary>The same as text</summary><pre>{_e(report.table)}</pre>"
               "</details>")
    return "\n".join(out)


def _figures(paths: Sequence[Path]) -> str:
    out = ["<h2>Figures</h2>"]
    for path in paths:
        data = base64.b64encode(path.read_bytes()).decode("ascii")
        out.append(f"<figure><img alt=\"{_e(path.stem)}\" src=\"data:image/png;base64,{data}\">"
                   f"<figcaption>{_e(path.name)}</figcaption></figure>")
    if not paths:
        out.append("<p class=\"note\">The recordings allow no figure.</p>")
    return "\n".join(out)


def page(report: Report) -> str:
    """The report as one HTML document (see the module docstring)."""
    names = ", ".join(s.path.name for s in report.sweeps)
    return "\n".join([
        "<!DOCTYPE html>", "<html lang=\"en\">", "<head>", "<meta charset=\"utf-8\">",
        "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">",
        f"<title>biped_opt report: {_e(names)}</title>", f"<style>{_STYLE}</style>", "</head>",
        "<body>", f"<h1>Report of {_e(names)}</h1>",
        "<p>Sweeps recorded by biped_opt, analysed offline: the nonsmooth points of their "
        "outcomes (and of optimal values and policies), the figures, and where they come "
        "from.</p>",
        _provenance(report), _inputs(report.sweeps), _nonsmooth(report),
        _figures(report.figures), "</body>", "</html>", ""])


def write_page(report: Report, out_dir: Path) -> Path:
    """Write :func:`page` to ``out_dir / report.html`` (complete or not at all)."""
    path = Path(out_dir) / PAGE_NAME
    partial = path.with_name(path.name + ".partial")
    partial.write_text(page(report), encoding="utf-8")
    partial.replace(path)
    return path
