"""Systems by name or from a user's file (SYSTEMS.md Sec. 4).

``load_system("rocking_bar")`` builds a library system (``solo12``, ``bolt`` and ``talos`` from
their vendored URDFs); ``load_system("robot.urdf:contacts=A+B")`` imports a robot's URDF
(:mod:`biped_opt.systems.urdf`, SYSTEMS.md Sec. 4a); ``load_system("path/to/file.py")`` runs
a plain Python file that builds one with the :class:`~biped_opt.systems.description.System`
API and leaves it in a module-level variable ``SYSTEM`` (or as the only System it defines), or
defines a factory ``make_system(**arguments)``: ``load_system("chain.py:links=5")`` calls it with
the arguments (:mod:`biped_opt.system_spec`; without arguments, a file with a factory and no
System calls it with its defaults). The file may import modules that lie beside it; each load
imports them afresh, and the system's ``reads`` lists every file it read (the caches key on
them). A mistake in the file is one :class:`SystemDescriptionError` naming the file, the line
and what is wrong; later messages about the system name the file too.
"""

from __future__ import annotations

import re
import runpy
import sys
import threading
import traceback
from pathlib import Path
from typing import Any

from biped_opt.errors import InvalidInputError, quoted
from biped_opt.system_spec import FACTORY, parse_file_spec
from biped_opt.systems.description import System, SystemDescriptionError
from biped_opt.systems.library import BY_NAME, LIBRARY, ROBOTS, SIZES, chain, walker

__all__ = ["load_system", "library_size", "WALKER", "CHAIN", "LIBRARY_PATTERNS"]

#: library names of walkers with n legs and an input law, and with the feet's offsets as
#: parameters (the pieces study's variant): walker4, walker3_decoupled, walker2_coupled_offsets
WALKER = re.compile(
    r"^walker(?P<n>[1-9][0-9]?)(?:_(?P<law>coupled|decoupled))?(?P<offsets>_offsets)?$")
#: library names of planar chains by their number of coordinates d = 3 + 2 segments: chain7
CHAIN = re.compile(r"^chain(?P<d>5|7|9|11)$")
#: the library's names beyond LIBRARY's, for messages
LIBRARY_PATTERNS = ("walkerN[_coupled|_decoupled][_offsets], chain5|7|9|11, quadruped, "
                    "biped_smooth, rocking_bar_soft, "
                    + ", ".join(ROBOTS))


def library_size(name: str) -> tuple[int, int] | None:
    """(constraints, coordinates) of the library system ``name`` from its name alone (nothing
    is built), or None when ``name`` is no library system."""
    if name in SIZES:
        return SIZES[name]
    match = WALKER.match(name)
    if match:  # (the offsets variant has a clock coordinate too)
        return int(match["n"]), 3 + 2 * int(match["n"]) + (match["offsets"] is not None)
    match = CHAIN.match(name)
    if match:
        return 2, int(match["d"])
    return None


def load_system(spec: str | Path | System) -> System:
    """A System from a library name, a path to a ``.py`` file, or a System (returned as is)."""
    if isinstance(spec, System):
        return spec
    text = str(spec)
    if text in LIBRARY:
        return LIBRARY[text]()
    if text in BY_NAME:
        return BY_NAME[text]()
    match = WALKER.match(text)
    if match:
        return walker(int(match["n"]), match["law"] or "coupled",
                      offsets=match["offsets"] is not None)
    match = CHAIN.match(text)
    if match:
        return chain((int(match["d"]) - 3) // 2)
    try:
        file = parse_file_spec(text)
    except InvalidInputError as exc:
        raise SystemDescriptionError(str(exc)) from None
    if file is None:
        raise SystemDescriptionError(
            f"unknown system {quoted(text)}: neither a library system "
            f"({', '.join(LIBRARY)}, {LIBRARY_PATTERNS}) nor a .py or .urdf file")
    path = file.path
    if not path.is_file():
        raise SystemDescriptionError(f"{path}: no such system file")
    if path.suffix == ".urdf":
        from biped_opt.systems.urdf import from_file_arguments

        robot = from_file_arguments(path, dict(file.arguments))
        robot.source = str(file)
        robot.reads = (path.resolve(),)
        return robot
    namespace, reads = _run(path)
    found = [v for v in namespace.values() if isinstance(v, System)]
    factory = namespace.get(FACTORY)
    factory_made = bool(file.arguments) or ("SYSTEM" not in namespace and not found
                                            and factory is not None)
    if factory_made:
        if not callable(factory):
            raise SystemDescriptionError(
                f"{path}: takes no arguments (it defines no function {FACTORY}(...))")
        system = _call(path, factory, dict(file.arguments))
    else:
        system = namespace.get("SYSTEM")
        if system is None:
            if len(found) != 1:
                raise SystemDescriptionError(
                    f"{path}: defines {len(found)} System objects; name the one to use SYSTEM")
            system = found[0]
    if not isinstance(system, System):
        what = f"{FACTORY} must return" if factory_made else "SYSTEM must be"
        raise SystemDescriptionError(
            f"{path}: {what} a biped_opt.systems.System, got {type(system).__name__}")
    system.source = str(file)
    system.reads = tuple(reads)
    return system


_RUNNING = threading.Lock()


def _run(path: Path) -> tuple[dict[str, Any], list[Path]]:
    """Run a system file with its folder first on ``sys.path``; its namespace and the files it
    read: itself, then the modules it imported from its folder, which leave ``sys.modules``
    again so the next load reads them afresh."""
    folder = path.resolve().parent
    with _RUNNING:  # (sys.path and sys.modules are the process's)
        before = set(sys.modules)
        sys.path.insert(0, str(folder))
        try:
            namespace = runpy.run_path(str(path), run_name="biped_opt_system")
        except SystemDescriptionError as exc:
            raise SystemDescriptionError(f"{path}:{_line(exc, path)} {exc}") from None
        except Exception as exc:  # the user's code: where and what, never our traceback
            raise SystemDescriptionError(
                f"{path}:{_line(exc, path)} {type(exc).__name__}: {exc}") from None
        finally:
            sys.path.remove(str(folder))
            helpers = []
            for name in set(sys.modules) - before:
                where = getattr(sys.modules[name], "__file__", None)
                if where and Path(where).resolve().is_relative_to(folder):
                    helpers.append(Path(where).resolve())
                    del sys.modules[name]
    return namespace, [path.resolve(), *sorted(helpers)]


def _call(path: Path, factory: Any, arguments: dict[str, Any]) -> Any:
    """``factory(**arguments)``, its failures named like the file's own."""
    try:
        return factory(**arguments)
    except SystemDescriptionError as exc:
        raise SystemDescriptionError(f"{path}:{_line(exc, path)} {exc}") from None
    except TypeError as exc:  # a wrong argument name, most likely
        raise SystemDescriptionError(f"{path}: {FACTORY}: {exc}") from None
    except Exception as exc:
        raise SystemDescriptionError(
            f"{path}:{_line(exc, path)} {type(exc).__name__}: {exc}") from None


def _line(exc: BaseException, path: Path) -> str:
    """`` line N:`` of the deepest frame of ``exc`` inside the user's file (empty if none)."""
    target = str(path.resolve())
    lines = [f.lineno for f in traceback.extract_tb(exc.__traceback__)
             if str(Path(f.filename).resolve()) == target]
    return f" line {lines[-1]}:" if lines else ""
