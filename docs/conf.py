"""Sphinx configuration of biped_opt's manual (``make docs``): Markdown pages through MyST, the
API reference from the package's docstrings, warnings as errors (the Makefile passes -W)."""

from __future__ import annotations

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from biped_opt.version import __version__  # noqa: E402

project = "biped_opt"
author = "the biped_opt developers"
copyright = "the biped_opt developers"  # noqa: A001 (Sphinx's name)
release = __version__
version = __version__

extensions = ["myst_parser", "sphinx.ext.autodoc", "sphinx.ext.autosummary",
              "sphinx.ext.viewcode"]
#: one page per module of the API reference, written at build time (docs/reference/generated)
autosummary_generate = True
autosummary_imported_members = False
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build"]
myst_heading_anchors = 3
myst_enable_extensions = ["colon_fence"]
autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": True,
                           # (a package that re-exports its modules' names documents them once,
                           # where they are defined)
                           "ignore-module-all": True}
autodoc_member_order = "bysource"
autodoc_typehints = "description"
html_theme = "alabaster"
html_title = f"biped_opt {version}"


_CITATION = re.compile(r"^(?P<indent>\s*)\.\. \[(?P<n>\d+)\] (?P<rest>.*)$")


def _plain_text(app, what, name, obj, options, lines):  # noqa: ARG001 (Sphinx's signature)
    """The docstrings are read as plain text in the source, and rendered as such:

    - norms and absolute values are written |x|, which reStructuredText would take for a
      substitution: the bars are escaped, but on the rows of a grid table;
    - the paper is cited as [1]_ with its reference below, ``.. [1] ...``: kept as the plain
      "[1]" and a paragraph, since a module's first sentence (citing the paper more than once)
      is also shown in the API's summary tables, where no footnote [1] is defined."""
    follows = False
    for k, line in enumerate(lines):
        if "|" in line and not line.lstrip().startswith(("|", "+")):
            line = line.replace("|", "\\|")
        line = re.sub(r"\[(\d+)\]_", r"[\1]", line)
        cited = _CITATION.match(line)
        if cited:
            line = f"{cited['indent']}[{cited['n']}] {cited['rest']}"
            follows = True
        elif follows and line.startswith("   "):
            line = line[3:]
        else:
            follows = False
        lines[k] = line


def setup(app):
    app.connect("autodoc-process-docstring", _plain_text)
