"""Sphinx configuration of biped_opt's manual (``make docs``): Markdown pages through MyST, the
API reference from the package's docstrings, warnings as errors (the Makefile passes -W)."""

from __future__ import annotations

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


def _plain_bars(app, what, name, obj, options, lines):  # noqa: ARG001 (Sphinx's signature)
    """The docstrings write norms and absolute values as |x| (plain text, as read in the
    source); reStructuredText would take |x| for a substitution. Bars are escaped, but on the
    rows of a grid table."""
    for k, line in enumerate(lines):
        if "|" in line and not line.lstrip().startswith(("|", "+")):
            lines[k] = line.replace("|", "\\|")


def setup(app):
    app.connect("autodoc-process-docstring", _plain_bars)
