"""Systems by name or from a user's file (SYSTEMS.md Sec. 4).

``load_system("rocking_bar")`` builds a library system; ``load_system("path/to/file.py")`` runs
a plain Python file that builds one with the :class:`~biped_opt.systems.description.System`
API and leaves it in a module-level variable ``SYSTEM`` (or as the only System it defines). A
mistake in the file is one :class:`SystemDescriptionError` naming the file, the line and what is
wrong; later messages about the system name the file too.
"""

from __future__ import annotations

import re
import runpy
import traceback
from pathlib import Path

from biped_opt.errors import quoted
from biped_opt.systems.description import System, SystemDescriptionError
from biped_opt.systems.library import LIBRARY, walker

__all__ = ["load_system", "WALKER"]

#: library names of walkers with n legs and an input law: walker4, walker3_decoupled
WALKER = re.compile(r"^walker(?P<n>[1-9][0-9]?)(?:_(?P<law>coupled|decoupled))?$")


def load_system(spec: str | Path | System) -> System:
    """A System from a library name, a path to a ``.py`` file, or a System (returned as is)."""
    if isinstance(spec, System):
        return spec
    text = str(spec)
    if text in LIBRARY:
        return LIBRARY[text]()
    match = WALKER.match(text)
    if match:
        return walker(int(match["n"]), match["law"] or "coupled")
    path = Path(text)
    if path.suffix != ".py":
        raise SystemDescriptionError(
            f"unknown system {quoted(text)}: neither a library system "
            f"({', '.join(LIBRARY)}, walkerN[_coupled|_decoupled]) nor a .py file")
    if not path.is_file():
        raise SystemDescriptionError(f"{path}: no such system file")
    try:
        namespace = runpy.run_path(str(path), run_name="biped_opt_system")
    except SystemDescriptionError as exc:
        raise SystemDescriptionError(f"{path}:{_line(exc, path)} {exc}") from None
    except Exception as exc:  # the user's code: where and what, never our traceback
        raise SystemDescriptionError(
            f"{path}:{_line(exc, path)} {type(exc).__name__}: {exc}") from None
    system = namespace.get("SYSTEM")
    if system is None:
        found = [v for v in namespace.values() if isinstance(v, System)]
        if len(found) != 1:
            raise SystemDescriptionError(
                f"{path}: defines {len(found)} System objects; name the one to use SYSTEM")
        system = found[0]
    if not isinstance(system, System):
        raise SystemDescriptionError(
            f"{path}: SYSTEM must be a biped_opt.systems.System, got {type(system).__name__}")
    system.source = str(path)
    return system


def _line(exc: BaseException, path: Path) -> str:
    """`` line N:`` of the deepest frame of ``exc`` inside the user's file (empty if none)."""
    target = str(path.resolve())
    lines = [f.lineno for f in traceback.extract_tb(exc.__traceback__)
             if str(Path(f.filename).resolve()) == target]
    return f" line {lines[-1]}:" if lines else ""
