"""What a request may name: systems and problems of the library or, by name, of the directories
the operator configured for the node (parameter ``system_paths``); never a path.

A system or problem file is Python (or names a Python file) that the node runs, so a request
(an ``OptimalPolicy`` request, a study work item, a ``/biped/study`` goal) names one only as a
plain name (letters, digits, ``_``; at most :data:`MAX_NAME` characters): ``walker3`` is a
library system, ``hopper`` is ``<dir>/hopper.py`` or else ``<dir>/hopper.urdf`` (a robot's URDF,
imported with the importer's defaults: floating base, the collision spheres and boxes at the
tree's ends as contacts; a request carries no options) in the first configured directory that
has one.
A problem name is one the system declares, else ``<dir>/<name>.yaml`` (``.yml``, ``.py``). A
problem file's ``system`` key is read the same way (a name; or ``x.py``, a file beside it).

The sizes a node accepts (:class:`SystemLimits`: legs, coordinates) are checked before anything
is derived: a library walker by its name, a file's system right after its description is built.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from biped_opt.errors import InvalidInputError, InvalidParameterError, quoted

if TYPE_CHECKING:
    from biped_opt.control.problems import Problem
    from biped_opt.studies.study import StudyLimits
    from biped_opt.systems.description import System

__all__ = ["MAX_NAME", "PROBLEM_SUFFIXES", "SYSTEM_SUFFIXES", "FILE_SUFFIXES", "Names",
           "SystemLimits", "Sources", "check_name", "name_of", "directories",
           "declare_request_limits", "request_study", "check_maneuver_of", "check_problem_on"]

#: longest system, problem or worker name a request may give
MAX_NAME = 64
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
#: suffixes of problem files, in the order they are looked for
PROBLEM_SUFFIXES = (".yaml", ".yml", ".py")
#: suffixes of system files, in the order they are looked for in a directory of system_paths
SYSTEM_SUFFIXES = (".py", ".urdf")
#: suffixes of any file a name stands for (its stem)
FILE_SUFFIXES = (*PROBLEM_SUFFIXES, ".urdf")
#: defaults of the node parameters max_legs and max_coordinates
MAX_LEGS, MAX_COORDINATES = 6, 16
#: defaults of a node's limits on a study (parameters max_points, max_num, max_values) and on
#: the text of a request's study (max_request_chars)
MAX_POINTS, MAX_NUM, MAX_VALUES, MAX_REQUEST_CHARS = 10_000, 2001, 1000, 65536


def check_name(field: str, text: str, what: str = "system") -> str:
    """``text`` if it is a plain name; else one line saying what a request may give."""
    if not isinstance(text, str) or len(text) > MAX_NAME or not _NAME.fullmatch(text):
        size = f"at most {MAX_NAME} " if isinstance(text, str) and len(text) > MAX_NAME else ""
        source = {"system": "a library system", "problem": "one the system declares"}
        where = (f": a request names {source[what]} or one in the node's system_paths, never "
                 "a file" if what in source else "")
        raise InvalidInputError(
            f"{field}: {quoted(text)} is not a {what} name ({size}letters, digits and _){where}")
    return text


def request_study(text: str, max_chars: int, *, yaml_too: bool = False) -> Any:
    """What the study text of a work item (JSON) or of a goal (``yaml_too``: JSON or YAML)
    holds, its length checked first (parameter max_request_chars); anything the parser
    refuses (also a recursion too deep or an integer of more digits than Python converts) is
    one line."""
    if len(text) > max_chars:
        raise InvalidInputError(f"study: {len(text)} characters; at most {max_chars} "
                                "(parameter max_request_chars)")
    if not yaml_too:
        try:
            return json.loads(text)
        except (ValueError, RecursionError) as exc:
            raise InvalidInputError(f"study: not JSON ({type(exc).__name__}: "
                                    f"{str(exc)[:100]})") from None
    import yaml

    try:
        return yaml.safe_load(text)
    except (yaml.YAMLError, ValueError, RecursionError) as exc:
        raise InvalidInputError(
            f"study: neither JSON nor YAML ({type(exc).__name__})") from None


def name_of(source: str) -> str:
    """The name a request gives for a library name or a system/problem file (its stem)."""
    return Path(source).stem if Path(source).suffix in FILE_SUFFIXES else source


def _in_library(name: str) -> bool:
    """Whether ``name`` is a library system (``walkerN[_law]``, ``chainD``, ``quadruped``
    included)."""
    from biped_opt.systems.files import library_size

    return library_size(name) is not None


def _beside(text: str) -> bool:
    """Whether a problem file's ``system`` names a file beside it (``x.py`` or ``x.urdf``, x
    a plain name)."""
    path = Path(text)
    return path.suffix in SYSTEM_SUFFIXES and _NAME.fullmatch(text[:-len(path.suffix)]) is not None


def _inside(field: str, folder: Path, path: Path) -> Path:
    """``path`` (a file found in ``folder`` of system_paths) resolved, if it stays in
    ``folder``: a symbolic link to a file elsewhere is refused, since the node would run
    whatever it points to and the operator listed only the directory."""
    real = path.resolve()
    if not real.is_relative_to(folder.resolve()):
        raise InvalidInputError(
            f"{field}: {path.name} in the node's system_paths is a link to a file outside "
            "its directory; refused (only files in a listed directory are served)")
    return real


def directories(values: Iterable[Any]) -> tuple[Path, ...]:
    """The ``system_paths`` parameter's directories, absolute; a missing one is an error."""
    out = []
    for value in values:
        text = str(value).strip()
        if not text:
            continue
        path = Path(text).expanduser().resolve()
        if not path.is_dir():
            raise InvalidParameterError(f"system_paths: {text}: no such directory")
        out.append(path)
    return tuple(out)


def check_maneuver_of(described: Any, maneuver: str) -> None:
    """``maneuver`` must be one of the described system's; the error names the field."""
    if maneuver not in described.maneuvers:
        raise InvalidInputError(
            f"maneuver: {described.name} has no maneuver {quoted(maneuver)} "
            f"(maneuvers: {', '.join(described.maneuvers) or 'none'})")


def check_problem_on(found: Problem, described: Any, maneuver: str) -> Problem:
    """``found``, a request's problem, must be on the requested system (``described``; None:
    any) and on ``maneuver``; each error names the field."""
    if described is not None and found.facts.name != described.name:
        raise InvalidInputError(
            f"problem: {found.name} is a problem on {found.facts.name}, not on "
            f"{described.name}")
    if found.maneuver != maneuver:
        raise InvalidInputError(
            f"maneuver: problem {found.name} is on maneuver {found.maneuver!r}, not "
            f"{quoted(maneuver)}")
    return found


@dataclass(frozen=True, kw_only=True)
class SystemLimits:
    """The largest systems a node derives and compiles (node parameters ``max_legs``: unilateral
    constraints, 2^n contact modes; ``max_coordinates``)."""

    max_legs: int = MAX_LEGS
    max_coordinates: int = MAX_COORDINATES

    def __post_init__(self) -> None:
        if self.max_legs < 1 or self.max_coordinates < 1:
            raise InvalidParameterError(
                f"max_legs and max_coordinates must be >= 1, got {self.max_legs}, "
                f"{self.max_coordinates}")

    def check_library(self, field: str, name: str) -> None:
        """A library system's size from its name alone (nothing built yet: building the
        quadruped's description and derivation take seconds)."""
        from biped_opt.systems.files import library_size

        size = library_size(name)
        if size is not None:
            self._check_size(field, name, *size)

    def check(self, field: str, system: System) -> None:
        """A described system's size, before it is derived."""
        self._check_size(field, system.name, len(system.constraints), len(system.q))

    def _check_size(self, field: str, name: str, legs: int, coordinates: int) -> None:
        if legs > self.max_legs or coordinates > self.max_coordinates:
            raise InvalidInputError(
                f"{field}: {name} has {legs} constraints and {coordinates} coordinates; this "
                f"node serves at most {self.max_legs} and {self.max_coordinates} "
                "(parameters max_legs, max_coordinates)")


@dataclass(frozen=True, kw_only=True)
class Names:
    """What a request names, checked (:meth:`Sources.check_request`) and resolved: ``source``
    what :func:`biped_opt.simulation.facts.describe` loads (a library name or the path of a
    file of system_paths; "" when the request names no system: the biped, or the system its
    problem file names), ``problem`` and ``maneuver`` plain names (``problem`` "": the one
    named like the maneuver; ``maneuver`` "": a study's). ``checked``: the system's description
    was built, its size checked and the problem or maneuver found in it (a library system; a
    file's description runs its code, so that waits for the compile)."""

    source: str
    problem: str
    maneuver: str
    checked: bool


@dataclass(frozen=True)
class Sources:
    """Resolves the names a request gives (see the module docstring)."""

    system_paths: tuple[Path, ...] = ()
    limits: SystemLimits = SystemLimits()

    def system(self, field: str, text: str) -> str:
        """What :func:`biped_opt.simulation.facts.describe` loads for the system name ``text``:
        the library name itself or the absolute path of ``<dir>/<name>.py`` (else
        ``<dir>/<name>.urdf``)."""
        from biped_opt.systems.files import LIBRARY_PATTERNS
        from biped_opt.systems.library import LIBRARY

        name = check_name(field, text)
        if _in_library(name):
            self.limits.check_library(field, name)
            return name
        for folder in self.system_paths:
            for suffix in SYSTEM_SUFFIXES:
                path = folder / f"{name}{suffix}"
                if path.is_file():
                    return str(_inside(field, folder, path))
        where = (f"nor {name}.py or {name}.urdf in the node's system_paths" if self.system_paths
                 else "and this node has no system_paths")
        raise InvalidInputError(
            f"{field}: unknown system {quoted(name)}: not a library system "
            f"({', '.join(LIBRARY)}, {LIBRARY_PATTERNS}) {where}")

    def problem_file(self, field: str, text: str) -> Path | None:
        """``<dir>/<name>.yaml`` (.yml, .py) of the problem name ``text``, or None."""
        return self._problem_path(check_name(field, text, "problem"))

    def _problem_path(self, name: str) -> Path | None:
        """:meth:`problem_file` of a name already checked."""
        for folder in self.system_paths:
            for suffix in PROBLEM_SUFFIXES:
                path = folder / f"{name}{suffix}"
                if path.is_file():
                    return _inside("problem", folder, path)
        return None

    def check_request(self, system: str, problem: str, maneuver: str | None = None
                      ) -> Names:
        """A request's names (``system`` "": the biped; ``maneuver`` None: a study's, which
        names no compile), and what can be checked of them on a library system without
        compiling anything (its description is cheap to build; not the quadruped's, which waits
        for the compiler like a file's): the problem declared or a file
        of system_paths, else the maneuver. Refuses at once what a compile would only refuse
        later, so that names no compile can serve never reach the compile queue. Returns them
        resolved, for :meth:`problem`."""
        if problem:
            check_name("problem", problem, "problem")
        if maneuver is not None:
            check_name("maneuver", maneuver, "maneuver")
        source = self.system("system", system) if system else "biped"
        from biped_opt.systems.library import BY_NAME

        names = Names(source=source if system else "", problem=problem,
                      maneuver=maneuver or "",
                      checked=Path(source).suffix not in SYSTEM_SUFFIXES
                      and source not in BY_NAME)
        if not names.checked:
            # a file's description runs its code (a URDF's import builds a tree of bodies:
            # seconds for a humanoid), and a library system built only when named
            # takes seconds to describe: either waits for the compiler, never the service
            return names
        described = self.describe("system", source)
        if problem:
            if problem not in described.problems and self._problem_path(problem) is None:
                raise self._no_problem(described, problem)
        elif maneuver is not None:
            check_maneuver_of(described, maneuver)
        return names

    def _no_problem(self, described: System, problem: str) -> InvalidInputError:
        return InvalidInputError(
            f"problem: {described.name} declares no problem {quoted(problem)} "
            f"(problems: {', '.join(described.problems) or 'none'}) and "
            + ("system_paths has no such file" if self.system_paths
               else "this node has no system_paths"))

    def describe(self, field: str, source: str) -> System:
        """The description of a resolved system, its size checked before anything derives."""
        from biped_opt.errors import BipedOptError
        from biped_opt.simulation.facts import describe

        try:
            system = describe(source)
        except BipedOptError as exc:
            raise InvalidInputError(f"{field}: {exc}") from None
        self.limits.check(field, system)
        return system

    def problem(self, names: Names) -> Problem:
        """The problem of a request's names (:meth:`check_request`; ``problem`` "": the one named
        like the maneuver), which must be on the maneuver. Checks only what the names' check
        could not: a system file's description (its size, its maneuver), the problem found (on
        the system and maneuver asked; the size of the system a problem file names). Runs the
        system's description (a file's code): call it where a slow or failing description holds
        up nobody else."""
        from biped_opt.control.problems import (
            Problem,
            describe,
            get_problem,
            load_problem,
            read_yaml,
        )
        from biped_opt.errors import BipedOptError

        source, problem, maneuver = names.source, names.problem, names.maneuver
        name = problem or maneuver
        described = None
        if source or not problem:
            if names.checked:  # (described, its size and the maneuver checked already)
                described = describe(source or "biped")
            else:
                described = self.describe("system", source or "biped")
                if not problem:
                    check_maneuver_of(described, maneuver)
        declared = described is not None and name in described.problems
        path = None if declared else self._problem_path(name)
        try:
            if path is None:
                found = get_problem(source or "biped", name)
            elif path.suffix == ".py":
                found = load_problem(path)
            else:
                spec = read_yaml(path)
                if not isinstance(spec, Mapping):
                    raise InvalidParameterError(f"{path}: must hold a mapping")
                spec = dict(spec)
                spec["system"] = self._file_system(path, spec.get("system"), source)
                spec.setdefault("name", path.stem)
                found = Problem.from_spec(spec, where=str(path))
        except BipedOptError as exc:
            raise InvalidInputError(f"problem: {exc}") from None
        if found.description is not described:  # (a problem file's system)
            self.limits.check("system", found.description)
        return check_problem_on(found, described, maneuver)

    def _file_system(self, path: Path, value: Any, source: str) -> str:
        """The system a problem file names: absent, the request's (else the biped); ``x.py``
        a file beside it; else a name as a request would give it."""
        if value is None:
            return source or "biped"
        text = str(value)
        if _beside(text):
            return str(_inside(f"{path.name}: system", path.parent, path.parent / text))
        return self.system(f"{path.name}: system", text)

    def study(self, system: str, problem: str | None) -> tuple[str, str | None]:
        """The ``system`` and ``problem`` a :class:`~biped_opt.studies.study.Study` loads for a
        study
        that names them: the system resolved as :meth:`system` (and described, its size
        checked); the problem a declared name (kept) or the path of its file, whose ``system``
        key must be absent, a library name or ``x.py`` beside it (what the study's loader
        reads itself)."""
        from biped_opt.control.problems import read_yaml

        source = self.system("system", system)
        described = self.describe("system", source)
        if not problem or problem in described.problems:
            return source, problem or None
        path = self.problem_file("problem", problem)
        if path is None:
            raise self._no_problem(described, problem)
        if path.suffix != ".py":
            spec = read_yaml(path)
            value = spec.get("system") if isinstance(spec, Mapping) else None
            text = "" if value is None else str(value)
            if text and not (_in_library(text) or _beside(text)):
                raise InvalidInputError(
                    f"problem: {path.name}: system: a study's problem file names a library "
                    f"system or a file beside it (x.py, x.urdf), got {quoted(text)}")
            self.limits.check_library(f"problem: {path.name}: system", text)
        return source, str(path)


def declare_request_limits(node: Any) -> tuple[Sources, StudyLimits, int]:
    """Declare and read the parameters that bound what a request may name and ask for
    (``system_paths``, ``max_legs``, ``max_coordinates``, ``max_points``, ``max_num``,
    ``max_values``, ``max_request_chars``): the node's :class:`Sources`, study limits and
    longest study text. A bad value stops the node (one line, status 2)."""
    from biped_opt.nodes.parameters import int_parameter, string_list_parameter
    from biped_opt.studies.study import StudyLimits

    for name, default in (("system_paths", []), ("max_legs", MAX_LEGS),
                          ("max_coordinates", MAX_COORDINATES), ("max_points", MAX_POINTS),
                          ("max_num", MAX_NUM), ("max_values", MAX_VALUES),
                          ("max_request_chars", MAX_REQUEST_CHARS)):
        node.declare_parameter(name, default)
    sources = Sources(
        directories(string_list_parameter(node, "system_paths")),
        SystemLimits(max_legs=int_parameter(node, "max_legs", 1),
                     max_coordinates=int_parameter(node, "max_coordinates", 1)))
    limits = StudyLimits(max_points=int_parameter(node, "max_points", 1),
                         max_num=int_parameter(node, "max_num", 3),
                         max_values=int_parameter(node, "max_values", 1))
    return sources, limits, int_parameter(node, "max_request_chars", 1)
