"""What a system's problems, studies and commands check against: its names, read without SymPy.

A :class:`SystemFacts` holds the names of a system (maneuvers, inputs, coordinates, velocities,
constraints, parameters with their defaults, the parameter s) and the problems it declares. A
problem checks its fields against them (:class:`biped_opt.control.problems.Problem`), a study its
grid, the command line its flags. :func:`biped_opt.simulation.compiled.system_facts` reads them
from the compiled systems' index when the system has been compiled before (nothing derived: a
cached start imports no SymPy), else from the description (:func:`describe`)."""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from biped_opt.systems.description import System

__all__ = ["SystemFacts", "describe"]


@dataclass(frozen=True)
class SystemFacts:
    """The names of a system and the problems it declares (see the module docstring)."""

    name: str
    #: how messages name the system (its file when it came from one)
    where_text: str
    source: str | None
    maneuvers: tuple[str, ...]
    inputs: tuple[str, ...]
    coordinates: tuple[str, ...]
    velocities: tuple[str, ...]
    constraints: tuple[str, ...]
    defaults: Mapping[str, float]
    #: the name of the initial-condition parameter s
    s: str
    #: the problems the description declares: name -> the keys of a problem file
    problems: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)

    def where(self) -> str:
        return self.where_text

    @classmethod
    def of(cls, system: System) -> SystemFacts:
        """The facts of a description."""
        return cls(name=system.name, where_text=system.where(), source=system.source,
                   maneuvers=tuple(system.maneuvers), inputs=tuple(system.u.names()),
                   coordinates=tuple(system.coordinate_names),
                   velocities=tuple(str(v) for v in system.dq),
                   constraints=tuple(system.constraints), defaults=dict(system.defaults),
                   s=str(system.s), problems={k: dict(v) for k, v in system.problems.items()})

    def as_json(self) -> dict[str, Any]:
        """The facts as the index keeps them. ``problems`` is None when a declared problem
        holds a value JSON cannot carry exactly (such a system's facts are then read from its
        description: :func:`system_facts`)."""
        problems: Any
        try:
            problems = _plain(self.problems)
            if json.loads(json.dumps(problems)) != problems:  # (NaN, a key not a string)
                problems = None
        except (TypeError, ValueError):
            problems = None
        return {"name": self.name, "where": self.where_text, "source": self.source,
                "maneuvers": list(self.maneuvers), "inputs": list(self.inputs),
                "coordinates": list(self.coordinates), "velocities": list(self.velocities),
                "constraints": list(self.constraints),
                "parameters": [[k, float(v)] for k, v in self.defaults.items()], "s": self.s,
                "problems": problems}

    @classmethod
    def from_json(cls, facts: Mapping[str, Any]) -> SystemFacts:
        """The facts :meth:`as_json` wrote (KeyError, TypeError or ValueError when they are not
        all there)."""
        if not isinstance(facts["problems"], Mapping):
            raise ValueError("the problems are not in the index")
        return cls(name=facts["name"], where_text=facts["where"], source=facts["source"],
                   maneuvers=tuple(facts["maneuvers"]), inputs=tuple(facts["inputs"]),
                   coordinates=tuple(facts["coordinates"]),
                   velocities=tuple(facts["velocities"]),
                   constraints=tuple(facts["constraints"]),
                   defaults={k: float(v) for k, v in facts["parameters"]}, s=facts["s"],
                   problems=facts["problems"])


def _plain(value: Any) -> Any:
    """``value`` with tuples as lists (what JSON gives back); TypeError for a value JSON does
    not carry (a SymPy number, a NumPy float32)."""
    if isinstance(value, Mapping):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if value is None or isinstance(value, (str, bool, int, float)):
        return value
    raise TypeError(f"not JSON: {value!r}")


_DESCRIPTIONS: dict[str, tuple[System, tuple[int | None, ...]]] = {}


def _stamps(paths: tuple[Path, ...]) -> tuple[int | None, ...]:
    def stamp(path: Path) -> int | None:
        try:
            return path.stat().st_mtime_ns
        except OSError:
            return None

    return tuple(stamp(p) for p in paths)


def describe(system: System | str) -> System:
    """:func:`load_system`, remembered per library name or file spec until a file it read (the
    system file or a module beside it) changes: building a description costs SymPy time that
    problems on the same system need not repeat."""
    from biped_opt.systems.description import System
    from biped_opt.systems.files import load_system

    if isinstance(system, System):
        return system
    text = str(system)
    found = _DESCRIPTIONS.get(text)
    if found is None or _stamps(found[0].reads) != found[1]:
        loaded = load_system(text)
        found = _DESCRIPTIONS[text] = (loaded, _stamps(loaded.reads))
    return found[0]
