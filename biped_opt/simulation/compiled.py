"""Compile a system description into its simulator, cached on disk by content, and run it.

The first use of a system writes the module :func:`biped_opt.codegen.render.render` makes into
the cache directory, named by a hash of its source, and imports it; Numba then compiles it on
the first call and keeps the machine code next to it (``__pycache__``), so a second process loads
instead of compiling. Parameter values are runtime data (an array argument): changing one never
changes the source, so it never recompiles.

A second process need not derive or render to find that module: after a render, a small index
entry (``systems/start/<key>.json``) maps a cheap key of the request -- a library name, or a system
file's path and content, together with a hash of the biped_opt sources and the versions of the
libraries the generator uses -- to the module's name and the facts simulating and optimising
need (names, maneuvers, inputs, parameter defaults, the declared problems:
:class:`~biped_opt.simulation.facts.SystemFacts`; the contact modes each input acts in). On a hit
the module is imported directly and SymPy is not touched: :attr:`CompiledSystem.system` and
:attr:`CompiledSystem.derived` are built when first read, and the gradients Theorem 1 needs are
a cached module of their own (:meth:`CompiledSystem.gradients`). Any change of the file or of
the package misses, and the slow path writes a fresh entry.

The cache lives in ``$BIPED_OPT_CACHE`` if set, else ``$XDG_CACHE_HOME/biped_opt`` (by default
``~/.cache/biped_opt``), under ``systems/``; deleting that directory is always safe.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import importlib.metadata
import importlib.util
import itertools
import json
import math
import os
import sys
import tempfile
import threading
import time
from collections.abc import Iterator, Mapping
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from biped_opt.codegen import abi, aot, precompile
from biped_opt.errors import InvalidInputError, InvalidParameterError
from biped_opt.simulation.facts import SystemFacts, describe
from biped_opt.simulation.options import DEFAULT_OPTIONS, SimulatorOptions
from biped_opt.simulation.scene import Scene
from biped_opt.simulation.trajectory import BatchResult, Trajectory
from biped_opt.system_spec import parse_file_spec
from biped_opt.version import PACKAGE_DIR

if TYPE_CHECKING:  # (imported where needed: SymPy and the generator are the slow part of a start)
    from biped_opt.systems.derive import DerivedSystem
    from biped_opt.systems.description import System

__all__ = ["BatchResult", "CompiledSystem", "SystemTrajectory", "Trajectory", "available_cores",
           "batch_thread_limit", "batch_threads", "cache_dir", "compile_system", "compiled_with",
           "kernels_cached", "run_batch", "simulate", "simulate_batch", "warm_up", "write_whole"]

Array = npt.NDArray[np.float64]

_LOCK = threading.Lock()
_LOADED: dict[str, ModuleType] = {}


def cache_dir() -> Path:
    """Where compiled systems live (see the module docstring)."""
    root = os.environ.get("BIPED_OPT_CACHE")
    if root:
        return Path(root) / "systems"
    xdg = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(xdg) / "biped_opt" / "systems"


def write_whole(path: Path, text: str) -> None:
    """``text`` into ``path``, written whole beside it then renamed: a concurrent process never
    reads half a file."""
    with tempfile.NamedTemporaryFile("w", dir=path.parent, suffix=".tmp", delete=False) as fh:
        fh.write(text)
    os.replace(fh.name, path)


#: the generated modules' names in sys.modules (Numba's cached code refers to them by name)
_MODULE_PREFIX = "biped_opt_systems_"


def _import(name: str, path: Path) -> ModuleType:
    """The cached module ``name`` (at ``path``), imported once per process (under _LOCK)."""
    if name not in _LOADED:
        spec = importlib.util.spec_from_file_location(_MODULE_PREFIX + name, path)
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = module
        spec.loader.exec_module(module)
        _LOADED[name] = module
    return _LOADED[name]


#: the generated module's constants a start from the index needs before (or without) the
#: module itself: array layouts, each maneuver's initial and final modes and when its terminal
#: guard is armed, the system's table
_AHEAD_CONSTANTS = ("NSTATE", "NCON", "NDOF", "SAMPLE_WIDTH", "EVENT_WIDTH", "INITIAL_MODE",
                    "FINAL_MODE", "TERM_AFTER_TOUCHDOWN", "SYSTEM_TABLE")
#: the y0 argument of the kernel that starts from the maneuver's own initial state at s
_FROM_S = np.empty(0)


def _constants(module: ModuleType) -> dict[str, Any]:
    """:data:`_AHEAD_CONSTANTS` of a generated module, as JSON values."""
    return {k: np.asarray(getattr(module, k)).tolist() for k in _AHEAD_CONSTANTS}


def _prepare_source(text: str) -> str:
    """The source of ``prepare_parameters`` in a generated module's text (plain Python of NumPy
    and math, see hoist.Hoisted), up to the next top-level statement."""
    start = text.index("\ndef prepare_parameters(") + 1
    lines = text[start:].split("\n")
    end = next(i for i, line in enumerate(lines[1:], 1) if line and not line[0].isspace())
    return "\n".join(lines[:end])


class _AheadModule:
    """A generated module seen through its ahead-of-time kernel (:mod:`biped_opt.codegen.aot`):
    the constants the index keeps, ``prepare_parameters`` read from the module's text, and
    ``entries``, the kernel's entry points it has (biped_opt.codegen.abi.ENTRIES: all of them
    from a kernel library, ``simulate_maneuver`` from an extension) with the system vector they
    take (``sv``: the table, no addresses; see biped_opt.codegen.abi). Any other attribute
    imports the module itself (and with it Numba) when first read."""

    def __init__(self, name: str, path: Path, constants: Mapping[str, Any],
                 kernel: Any) -> None:
        self._name, self._path = name, path
        for key, value in constants.items():
            setattr(self, key, np.array(value, dtype=np.int64) if isinstance(value, list)
                    else value)
        self.entries = {entry: getattr(kernel, entry) for entry in abi.ENTRIES
                        if callable(getattr(kernel, entry, None))}
        for call in abi.MODULE_CALLS:  # (a library has them: found directly)
            if callable(getattr(kernel, call, None)):
                setattr(self, call, getattr(kernel, call))
        self.sv = np.concatenate((np.zeros(abi.NFUNC, dtype=np.int64),
                                  np.asarray(constants["SYSTEM_TABLE"], dtype=np.int64)))
        namespace: dict[str, Any] = {"np": np, "math": math}
        exec(compile(_prepare_source(path.read_text()), str(path), "exec"), namespace)
        self.prepare_parameters = namespace["prepare_parameters"]

    def __getattr__(self, attr: str) -> Any:  # (only for what __init__ did not set)
        if attr.startswith("__"):
            raise AttributeError(attr)
        with _LOCK:
            module = _import(self._name, self._path)
        value = getattr(module, attr)
        setattr(self, attr, value)  # (found directly from now on)
        return value


#: the ahead-of-time views made in this process, by module name (one per module, as _LOADED)
_AHEAD: dict[str, _AheadModule] = {}


def _scene_for(system: System) -> dict[str, Any]:
    """Render the scene module of ``system`` into the cache (named by a hash of its text, like
    the simulator's) and the facts a :class:`~biped_opt.simulation.scene.Scene` reads."""
    from biped_opt.codegen.render import source_key
    from biped_opt.codegen.scene import render_scene, scene_facts

    text = render_scene(system)
    name = f"{system.name}_scene_{source_key(text)}"
    folder = cache_dir()
    path = folder / f"{name}.py"
    with _LOCK:
        folder.mkdir(parents=True, exist_ok=True)
        if not path.exists() or path.read_text() != text:
            write_whole(path, text)
    return {"module": name, **scene_facts(system)}


def _module_for(derived: DerivedSystem) -> tuple[str, ModuleType]:
    from biped_opt.codegen.render import render, source_key

    text = render(derived)
    name = f"{derived.system.name}_{source_key(text)}"
    folder = cache_dir()
    path = folder / f"{name}.py"
    with _LOCK:
        fresh = False
        if name not in _LOADED:
            folder.mkdir(parents=True, exist_ok=True)
            fresh = not path.exists() or path.read_text() != text
            if fresh:
                write_whole(path, text)
                # a new module: its event functions compile in a second process meanwhile
                precompile.start(path, _MODULE_PREFIX + name)
        module = _import(name, path)
    if fresh:  # (outside the lock: a compile of seconds must not hold up other systems)
        precompile.step_first(module)
    return name, module


_GENERATOR: list[str] = []


def _generator_key() -> str:
    """A hash of everything a rendered module may depend on besides the request: every source
    file of biped_opt (the generator, the library, the checks, the library robots' URDFs) and
    the versions of SymPy (its printing and common subexpressions) and SciPy (the DOP853
    tableau)."""
    if not _GENERATOR:
        digest = hashlib.sha256()
        root = PACKAGE_DIR
        for path in sorted([*root.rglob("*.py"), *root.rglob("*.urdf")]):
            digest.update(f"{path.relative_to(root).as_posix()}\0".encode())
            digest.update(path.read_bytes())
        for dist in ("sympy", "scipy"):
            digest.update(f"\0{dist} {importlib.metadata.version(dist)}".encode())
        _GENERATOR.append(digest.hexdigest())
    return _GENERATOR[0]


def _start_entry(spec: object) -> Path | None:
    """Where the index entry of a library name or a system file lives (None for a System
    object, or a file that cannot be read: those take the slow path)."""
    if not isinstance(spec, (str, Path)):
        return None
    text = str(spec)
    request = f"library\0{text}".encode()
    try:
        file = parse_file_spec(text)
    except InvalidInputError:
        return None  # (the slow path says what is wrong)
    if file is not None:
        try:
            content = file.path.read_bytes()
        except OSError:
            return None
        request = f"file\0{file.path}\0{file.key()}\0".encode() \
            + hashlib.sha256(content).digest()
    key = hashlib.sha256(_generator_key().encode() + b"\0" + request).hexdigest()[:32]
    return cache_dir() / "start" / f"{key}.json"


def _read_entry(entry: Path | None, *, ahead: bool = False
                ) -> tuple[dict[str, Any], ModuleType | _AheadModule] | None:
    """The facts and the module an index entry names, if both are there. ``ahead``: the module
    through its ahead-of-time kernel where that is built (else its build is started and the
    module imported as usual)."""
    try:
        facts = _entry_facts(entry)
        if facts is None:
            return None
        name = facts["module"]
        path = cache_dir() / f"{name}.py"
        scene = facts["scene"]["module"]
        with _LOCK:
            if name not in _LOADED and not path.is_file() or \
                    scene not in _LOADED and not (cache_dir() / f"{scene}.py").is_file():
                return None
            if ahead and name not in _LOADED and "constants" in facts:
                # (a module this process imported already is used as it is)
                if name not in _AHEAD:
                    ahead_kernel = aot.load(cache_dir(), name)
                    if ahead_kernel is not None:
                        _AHEAD[name] = _AheadModule(name, path, facts["constants"], ahead_kernel)
                if name in _AHEAD:
                    return facts, _AHEAD[name]
                aot.start(path, _MODULE_PREFIX + name, name)
            return facts, _import(name, path)
    except (OSError, ValueError, KeyError, TypeError):
        return None  # absent or unreadable: derive and render instead


def _entry_facts(entry: Path | None) -> dict[str, Any] | None:
    """The facts of an index entry, None when it is absent or a module the system file
    imported has changed since (OSError, ValueError, KeyError, TypeError when unreadable)."""
    if entry is None or not entry.is_file():
        return None
    facts = json.loads(entry.read_text())
    for path, digest in facts["depends"]:  # the modules a system file imported
        if _digest(Path(path)) != digest:
            return None
    return facts


def _digest(path: Path) -> str | None:
    """SHA-256 of a file's content (None if it cannot be read)."""
    try:
        return hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError:
        return None


def kernel_config(options: SimulatorOptions, sample_dt: float = 0.0,
                  touched_down: bool = False) -> Array:
    """The ``cfg`` vector the kernel takes (layout: biped_opt.codegen.abi's CFG_* indices).
    ``touched_down``: the trajectory continues after a touchdown, so a terminal event armed
    after the first touchdown is armed from the start."""
    cfg = np.empty(abi.CFG_SIZE)
    cfg[abi.CFG_T_END] = options.t_end
    cfg[abi.CFG_MAX_EVENTS] = options.max_events
    cfg[abi.CFG_RTOL] = options.rtol
    cfg[abi.CFG_ATOL] = options.atol
    cfg[abi.CFG_H_MAX] = options.h_max
    cfg[abi.CFG_SAMPLE_DT] = sample_dt
    cfg[abi.CFG_TOUCHED_DOWN] = float(touched_down)
    return cfg


def cached_size(system: str | Path) -> tuple[int, int] | None:
    """(constraints, coordinates) of a library system or system file the index names, read
    from the index alone (nothing derived, imported or run: a cached start stays one), else
    None."""
    try:
        facts = _entry_facts(_start_entry(system))
        return None if facts is None else (len(facts["constraints"]),
                                           len(facts["coordinates"]))
    except (OSError, ValueError, KeyError, TypeError):
        return None


def cached_facts(system: str | Path) -> SystemFacts | None:
    """The :class:`~biped_opt.simulation.facts.SystemFacts` of a library system or system file
    the index names, read from the index alone, else None."""
    try:
        facts = _entry_facts(_start_entry(system))
        return None if facts is None else SystemFacts.from_json(facts)
    except (OSError, ValueError, KeyError, TypeError):
        return None


def system_facts(system: System | SystemFacts | str | Path) -> SystemFacts:
    """The facts of a description, a library name or a system file: from the compiled systems'
    index when it names the system, else from its description."""
    if isinstance(system, SystemFacts):
        return system
    if isinstance(system, (str, Path)):
        cached = cached_facts(system)
        if cached is not None:
            return cached
    return SystemFacts.of(describe(system if not isinstance(system, Path) else str(system)))


def cached_module(system: str | Path) -> ModuleType | None:
    """The compiled module of a library system or system file when the index names it (read
    without deriving anything), else None."""
    found = _read_entry(_start_entry(system))  # (ahead=False: the module itself)
    if found is None:
        return None
    assert isinstance(found[1], ModuleType)
    return found[1]


def _write_entry(entry: Path, facts: dict[str, Any]) -> None:
    entry.parent.mkdir(parents=True, exist_ok=True)
    write_whole(entry, json.dumps(facts))


#: the one trajectory type under the name this module gave it first
SystemTrajectory = Trajectory


class CompiledSystem:
    """A system ready to simulate: derived, generated, imported (compiled on first call)."""

    def __init__(self, system: System | str, **parameters: float) -> None:
        self._spec = system
        self._system: System | None = None
        self._derived: DerivedSystem | None = None
        #: the generated module (or its ahead-of-time view, on a start from the index)
        self.module: Any = None
        self._shared: tuple[ModuleType, npt.NDArray[np.int64]] | None = None
        entry = _start_entry(system)
        cached = _read_entry(entry, ahead=True)
        if cached is None:
            facts = self._build(system)
            if entry is not None and _start_entry(system) == entry:  # (not edited meanwhile)
                _write_entry(entry, facts)
        else:
            facts, self.module = cached
        #: the generated module's name in the cache (its source's hash)
        self.module_name: str = facts["module"]
        self._gradients: ModuleType | None = None
        self._name: str = facts["name"]
        self._where: str = facts["where"]
        self._defaults: dict[str, float] = dict(facts["parameters"])
        self.maneuvers: tuple[str, ...] = tuple(facts["maneuvers"])
        self.inputs: tuple[str, ...] = tuple(facts["inputs"])
        self._constraints: tuple[str, ...] = tuple(facts["constraints"])
        self._options = [dataclasses.replace(DEFAULT_OPTIONS, max_events=events, t_end=horizon)
                         for events, horizon in facts["budgets"]]
        self._ranges = [(float(lo), float(hi)) for lo, hi in facts["ranges"]]
        self._coordinates: tuple[str, ...] = tuple(facts["coordinates"])
        #: the name of the maneuvers' initial-condition parameter s (the biped's th0)
        self.s_name: str = facts["s"]
        self._input_modes = {k: frozenset(v) for k, v in facts["input_modes"].items()}
        self._scene_facts: dict[str, Any] = facts["scene"]
        self._scene: Scene | None = None
        self._initial_modes = [int(v) for v in self.module.INITIAL_MODE]
        self._codes = {name: k for k, name in enumerate(self.maneuvers)}
        self._ninputs = len(self.inputs)
        self._no_samples = np.empty((0, self.module.SAMPLE_WIDTH))
        self._cfgs: dict[tuple[SimulatorOptions, float], Array] = {}
        # each maneuver's own options without samples, the common call: found without hashing
        self._maneuver_cfgs = [self._cfg(o, 0.0) for o in self._options]
        self.set_parameters(**parameters)

    def _build(self, spec: System | str) -> dict[str, Any]:
        """The slow path: load, derive, render, import; the facts an index entry keeps."""
        from biped_opt.systems.derive import derive
        from biped_opt.systems.files import load_system

        system = self._system = load_system(spec)
        derived = self._derived = derive(system)
        module_name, self.module = _module_for(derived)
        # (the applied forces: a system of bodies adds terms of no input to every mode)
        modes = {name: [mask for mask, f in enumerate(derived.applied) if f.has(symbol)]
                 for name, symbol in zip(system.u.names(), system.u)}
        return {"module": module_name, **SystemFacts.of(system).as_json(), "input_modes": modes,
                "budgets": [[m.description.max_events, m.description.horizon]
                            for m in derived.maneuvers.values()],
                "ranges": [list(m.description.s_range) for m in derived.maneuvers.values()],
                "scene": _scene_for(system),
                "constants": _constants(self.module),
                "depends": [[str(p), _digest(p)] for p in system.reads[1:]]}

    @property
    def system(self) -> System:
        """The description (built when first read after a start from the index)."""
        if self._system is None:
            from biped_opt.systems.files import load_system

            self._system = load_system(self._spec)
        return self._system

    @property
    def derived(self) -> DerivedSystem:
        """The derived quantities (SymPy; derived when first read after a start from the
        index)."""
        if self._derived is None:
            from biped_opt.systems.derive import derive

            self._derived = derive(self.system)
        return self._derived

    @property
    def name(self) -> str:
        return self._name

    def where(self) -> str:
        """How messages name the system (its file when it came from one)."""
        return self._where

    def gradients(self) -> ModuleType:
        """The module of the gradients Theorem 1's derivatives need
        (:mod:`biped_opt.codegen.gradients`): rendered with SymPy into the cache on first use,
        imported from there (plain NumPy) by every later process."""
        if self._gradients is None:
            name = f"{self.module_name}_gradients_{_generator_key()[:16]}"
            folder = cache_dir()
            path = folder / f"{name}.py"
            if not path.is_file():
                from biped_opt.codegen.gradients import render_gradients

                text = render_gradients(self.derived)
                with _LOCK:
                    folder.mkdir(parents=True, exist_ok=True)
                    write_whole(path, text)
            with _LOCK:
                self._gradients = _import(name, path)
        return self._gradients

    @property
    def scene(self) -> Scene:
        """How the system looks (:class:`~biped_opt.simulation.scene.Scene`: frames, shapes,
        contact points), read from its generated scene module (no SymPy)."""
        if self._scene is None:
            name = self._scene_facts["module"]
            with _LOCK:
                module = _import(name, cache_dir() / f"{name}.py")
            self._scene = Scene(self._name, self._scene_facts, module.scene_values,
                                self._constraints, getattr(module, "tree_values", None))
        return self._scene

    def input_modes(self, name: str) -> frozenset[int]:
        """The contact modes (bit masks) whose forces depend on input ``name``."""
        return self._input_modes[name]

    @property
    def coordinates(self) -> tuple[str, ...]:
        """The generalised coordinates' names in their declared order (the state is
        (q, q') in this order)."""
        return self._coordinates

    @property
    def constraints(self) -> tuple[str, ...]:
        """The constraints' names in their declared order (bit j of a contact mode is the
        j-th)."""
        return self._constraints

    def set_parameters(self, **parameters: float) -> None:
        """Parameter values (defaults overridden); runtime data, no recompilation."""
        values = dict(self._defaults)
        for key, value in parameters.items():
            if key not in values:
                raise InvalidParameterError(
                    f"{self._where}: unknown parameter {key!r} "
                    f"(parameters: {', '.join(values) or 'none'})")
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not math.isfinite(value):
                raise InvalidParameterError(
                    f"{self._where}: parameter {key!r} must be a finite number, "
                    f"got {value!r}")
            values[key] = float(value)
        raw = np.array(list(values.values()), dtype=np.float64)  # (the declared order)
        try:  # the values and what depends on them alone (see codegen._Hoisted)
            with np.errstate(divide="raise", invalid="raise", over="raise"):
                prepared = self.module.prepare_parameters(raw)
        except (ArithmeticError, ValueError, FloatingPointError) as exc:
            raise InvalidParameterError(
                f"{self._where}: these parameters give no invertible mass matrix "
                f"({exc})") from None
        self.parameters = values
        #: the parameter vector the generated module takes (values, then what depends on them)
        self.prepared = prepared

    def initial_mode(self, maneuver: str) -> int:
        """The contact mode (bit mask) ``maneuver`` starts in."""
        return self._initial_modes[self.code(maneuver)]

    def s_range(self, maneuver: str) -> tuple[float, float]:
        """The range of s ``maneuver`` declares valid (simulating outside it is allowed: other
        mode sequences appear there, which studies may want)."""
        return self._ranges[self.code(maneuver)]

    def maneuver_options(self, maneuver: str) -> SimulatorOptions:
        """The simulator's settings for ``maneuver``: the defaults with its own event budget
        and horizon (what :meth:`simulate` uses unless given other options)."""
        return self._options[self.code(maneuver)]

    def code(self, maneuver: str) -> int:
        """The generated module's index of ``maneuver``; an unknown name is an
        InvalidInputError listing the maneuvers."""
        code = self._codes.get(maneuver) if type(maneuver) is str else None
        if code is not None:
            return code
        try:
            return self.maneuvers.index(maneuver)
        except ValueError:
            raise InvalidInputError(
                f"{self._where}: unknown maneuver {maneuver!r} "
                f"(maneuvers: {', '.join(self.maneuvers) or 'none'})") from None

    def input_vector(self, inputs: Any) -> Array:
        """The system's input vector from a vector (the declared order, zero-padded), a mapping
        of input names or None (zeros); an unknown name, too many values or a value that is not
        a finite number is an InvalidInputError naming the input."""
        if type(inputs) is tuple and len(inputs) == self._ninputs > 0:
            # the common case, a full vector of numbers, checked in one call (per-element
            # checks and NumPy's would cost as much as a quarter of a trajectory): fsum
            # refuses what is not a number, and its sum is finite only if every term is
            try:
                finite = math.isfinite(math.fsum(inputs))
            except (TypeError, ValueError, OverflowError):  # (ValueError: inf - inf)
                finite = False
            if finite:
                return np.array(inputs, dtype=np.float64)
        u = np.zeros(max(len(self.inputs), 1))
        if inputs is None:
            return u
        if isinstance(inputs, dict):
            for key, value in inputs.items():
                if key not in self.inputs:
                    raise InvalidInputError(
                        f"{self._where}: unknown input {key!r} "
                        f"(inputs: {', '.join(self.inputs) or 'none'})")
                u[self.inputs.index(key)] = _number(f"{self._where}: {key}", value)
        else:
            try:
                values = np.asarray(inputs, dtype=np.float64).ravel()
            except (TypeError, ValueError):
                raise InvalidInputError(
                    f"{self._where}: inputs must be numbers, got {inputs!r}") from None
            if values.size > len(self.inputs) and not (
                    # (the zero-padded vector of a system without inputs, this method's own)
                    not self.inputs and values.size == 1 and values[0] == 0.0):
                raise InvalidInputError(
                    f"{self._where}: {values.size} inputs given, the system has "
                    f"{len(self.inputs)} ({', '.join(self.inputs) or 'none'})")
            u[: values.size] = values
        bad = np.flatnonzero(~np.isfinite(u))
        if bad.size:
            raise InvalidInputError(
                f"{self._where}: {self.inputs[bad[0]]} must be finite, got {u[bad[0]]}")
        return u

    def input_rows(self, inputs: npt.ArrayLike | None, n: int) -> Array:
        """(n, inputs) rows for a batch of n cases from one input vector for all (or None) or
        one row per case; the error names the input and the case."""
        width = max(len(self.inputs), 1)
        if inputs is None:
            return np.zeros((n, width))
        try:
            raw = np.asarray(inputs, dtype=np.float64)
        except (TypeError, ValueError):
            raise InvalidInputError(
                f"{self._where}: inputs must be numbers, got {inputs!r}") from None
        if raw.ndim <= 1 or (raw.ndim == 2 and raw.shape[0] == 1):  # one vector for all
            return np.tile(self.input_vector(raw.ravel()), (n, 1))
        if raw.ndim != 2 or raw.shape[0] != n or raw.shape[1] > len(self.inputs):
            raise InvalidInputError(
                f"{self._where}: inputs must have shape (<={len(self.inputs)},) or "
                f"({n}, <={len(self.inputs)}) for {n} cases, got {raw.shape}")
        rows = np.zeros((n, width))
        rows[:, : raw.shape[1]] = raw
        bad = np.argwhere(~np.isfinite(rows))
        if bad.size:
            k, i = bad[0]
            raise InvalidInputError(
                f"{self._where}: {self.inputs[i]} of case {k} must be finite, got {rows[k, i]}")
        return rows

    def _cfg(self, options: SimulatorOptions, sample_dt: float) -> Array:
        key = (options, sample_dt)
        cfg = self._cfgs.get(key)
        if cfg is None:
            cfg = self._cfgs[key] = kernel_config(options, sample_dt)
        return cfg

    def shared_kernel(self) -> tuple[ModuleType, npt.NDArray[np.int64]]:
        """The kernel every system shares (:mod:`biped_opt.codegen.kernel`) and this system's
        vector ``sv`` for it: its compiled functions' addresses, then its table
        (biped_opt.codegen.abi). Its functions are compiled here when first needed (or loaded
        from Numba's cache)."""
        if self._shared is None:
            from biped_opt.codegen import kernel

            m = self.module
            sv = np.concatenate((m.function_addresses(),
                                 np.asarray(m.SYSTEM_TABLE, dtype=np.int64)))
            self._shared = (kernel, sv)
        return self._shared

    def kernel_entry(self, entry: str) -> tuple[Any, npt.NDArray[np.int64]]:
        """An entry point of the kernel (biped_opt.codegen.abi.ENTRIES) and the system vector
        to call it with: the one compiled ahead with this system's module when the start found
        it (biped_opt.codegen.aot), else the shared kernel's (:meth:`shared_kernel`)."""
        m = self.module
        if isinstance(m, _AheadModule) and entry in m.entries:
            return m.entries[entry], m.sv
        kernel, sv = self.shared_kernel()
        return getattr(kernel, entry), sv

    def simulate(self, maneuver: str, s: float, inputs: Any = None, *,
                 options: SimulatorOptions = DEFAULT_OPTIONS,
                 sample_dt: float | None = None) -> Trajectory:
        """One maneuver at s (inputs by name in a dict, or a vector in the declared order).
        ``options`` left at ``DEFAULT_OPTIONS`` means :meth:`maneuver_options` (the
        maneuver's own budget); any other options are taken as given."""
        code = self.code(maneuver)
        if options is DEFAULT_OPTIONS:
            options = self._options[code]
        s = float(s)
        if not math.isfinite(s):
            raise InvalidInputError(f"{self._where}: s must be finite, got {s}")
        if sample_dt is not None and not (math.isfinite(sample_dt) and sample_dt > 0):
            raise InvalidInputError(f"sample_dt must be a positive number, got {sample_dt!r}")
        u = self.input_vector(inputs)
        m = self.module
        if sample_dt:
            dt = float(sample_dt)
            capacity = int(options.t_end / dt) + 4 * (options.max_events + 2) if dt > 0 else 0
            samples = np.zeros((capacity, m.SAMPLE_WIDTH)) if capacity else self._no_samples
            cfg = self._cfg(options, dt)
        else:
            samples = self._no_samples
            cfg = (self._maneuver_cfgs[code] if options is self._options[code]
                   else self._cfg(options, 0.0))
        return self._run(maneuver, code, s, u, options, cfg, samples if sample_dt else None,
                         _FROM_S, self._initial_modes[code])

    def _run(self, maneuver: str, code: int, s: float, u: Array, options: SimulatorOptions,
             cfg: Array, samples: Array | None, y0: Array, mode0: int) -> Trajectory:
        """One kernel call (from s, or from (y0, mode0) when y0 is a state) as a Trajectory."""
        m = self.module
        events = np.empty((options.max_events + 1, m.EVENT_WIDTH))
        y_out = np.empty(m.NSTATE)
        run, sv = self.kernel_entry("simulate_maneuver")
        status, t_f, mode_f, n_ev, n_s, nfev, nsteps, nrej, outcome = run(
            self.prepared, sv, code, s, u, cfg, self._no_samples if samples is None else samples,
            events, y_out, y0, mode0)
        return Trajectory.from_kernel(
            self._name, maneuver, s, tuple(u.tolist()[: self._ninputs]), status, t_f, outcome,
            y_out, mode_f, mode0 if y0.size else self._initial_modes[code], n_ev, events,
            None if samples is None else samples[: min(n_s, len(samples))], nfev, nsteps, nrej,
            self._constraints, (options.max_events, options.t_end))

    def advance(self, maneuver: str, y: npt.ArrayLike, mode: int, inputs: Any, span: float, *,
                sample_dt: float | None = None) -> Trajectory:
        """Integrate for ``span`` of time from the state ``y`` in contact mode ``mode`` (a step
        of a live simulator), with the events located as :meth:`simulate` locates them and
        ``maneuver``'s guards and event budget. One kernel call: it ends at ``span`` (status
        HORIZON: the step is done), at the maneuver's terminal event (status OK, ``t_final``
        < ``span``: continue from ``y_final`` and ``mode_final`` for the rest), or with a
        failure status. Times in the result are from the state given (t = 0)."""
        code = self.code(maneuver)
        m = self.module
        y0 = np.array(y, dtype=np.float64).ravel()
        if y0.size != m.NSTATE or not np.all(np.isfinite(y0)):
            raise InvalidInputError(f"{self._where}: the state must be {m.NSTATE} finite "
                                    f"numbers, got {y0.size}")
        span = float(span)
        if not (math.isfinite(span) and span > 0):
            raise InvalidInputError(f"span must be a positive number, got {span!r}")
        options = dataclasses.replace(self._options[code], t_end=span)
        u = self.input_vector(inputs)
        if sample_dt:
            dt = float(sample_dt)
            samples = np.zeros((int(span / dt) + 4 * (options.max_events + 2), m.SAMPLE_WIDTH))
        else:
            dt, samples = 0.0, None
        return self._run(maneuver, code, 0.0, u, options,
                         kernel_config(options, dt, touched_down=True), samples, y0, int(mode))

    def initial_state(self, maneuver: str, s: float) -> tuple[Array, int]:
        """``maneuver``'s initial state at s and its initial contact mode (the first sample of
        :meth:`simulate`, which the kernel records before its first step)."""
        tr = self.simulate(maneuver, s, options=dataclasses.replace(
            self._options[self.code(maneuver)], t_end=1e-9), sample_dt=1.0)
        assert tr.samples is not None and tr.samples[0, 0] == 0.0
        n = self.module.NSTATE
        return tr.samples[0, 1:1 + n].copy(), int(tr.samples[0, 1 + n])

    def simulate_batch(self, maneuver: str, s: npt.ArrayLike, inputs: npt.ArrayLike | None = None,
                       *, options: SimulatorOptions = DEFAULT_OPTIONS) -> BatchResult:
        """Many s (and input vectors, one row each or one for all) in parallel compiled threads
        (``options`` as in :meth:`simulate`)."""
        code = self.code(maneuver)
        if options is DEFAULT_OPTIONS:
            options = self._options[code]
        try:
            ss = np.atleast_1d(np.asarray(s, dtype=np.float64))
        except (TypeError, ValueError):
            raise InvalidInputError(f"{self._where}: s must be numbers, got {s!r}") from None
        if ss.ndim != 1:
            raise InvalidInputError(f"{self._where}: s must be a 1-D array, got shape {ss.shape}")
        if not np.all(np.isfinite(ss)):
            raise InvalidInputError(f"{self._where}: s must be finite")
        us = self.input_rows(inputs, ss.size)
        m = self.module
        events = np.zeros((ss.size, options.max_events + 1, m.EVENT_WIDTH))
        y_out = np.zeros((ss.size, m.NSTATE))
        outcome = np.zeros(ss.size)
        info = np.zeros((ss.size, 8))
        batch, sv = self.kernel_entry("simulate_batch_kernel")
        run_batch(batch, ss.size,
                  (self.prepared, sv, code, ss, us, self._cfg(options, 0.0), events, y_out, outcome,
                   info))
        return BatchResult.from_kernel(self._name, maneuver, ss, us, info, outcome, y_out, events,
                                       self._initial_modes[code], self._constraints)


#: the fewest cases a batch gives each thread: a thread's start and hand-over cost about one
#: trajectory of a small system, so fewer cases per thread would not pay for it
MIN_CASES_PER_THREAD = 8
#: each thread takes the work in about this many pieces, so that a thread whose core is busy
#: elsewhere takes fewer of them
PIECES_PER_THREAD = 8

_POOL: list[ThreadPoolExecutor] = []
_LIMIT = threading.local()


@contextlib.contextmanager
def batch_thread_limit(threads: int) -> Iterator[None]:
    """Batches started by this thread (inside the ``with``) use at most ``threads`` threads: a
    process that shares the machine with others of its kind (one optimiser node per core)
    keeps to its share."""
    before = getattr(_LIMIT, "threads", None)
    _LIMIT.threads = max(1, int(threads))
    try:
        yield
    finally:
        _LIMIT.threads = before


def available_cores() -> int:
    """The cores this process may run on (its CPU affinity; all of them where that is not
    known)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # (not on Linux)
        return max(1, os.cpu_count() or 1)


def batch_threads(n: int, cores: int | None = None) -> int:
    """Threads for a batch of ``n`` cases: one per :data:`MIN_CASES_PER_THREAD` cases, at most
    one per available core (and at most the calling thread's :func:`batch_thread_limit`)."""
    cores = available_cores() if cores is None else cores
    limit = getattr(_LIMIT, "threads", None)
    if limit is not None:
        cores = min(cores, limit)
    return max(1, min(cores, n // MIN_CASES_PER_THREAD))


def _pool() -> ThreadPoolExecutor:
    with _LOCK:
        if not _POOL:
            _POOL.append(ThreadPoolExecutor(max(1, available_cores() - 1),
                                            thread_name_prefix="biped_opt-batch"))
        return _POOL[0]


def run_batch(kernel: Any, n: int, args: tuple, threads: int | None = None) -> None:
    """``kernel(*args, start, stop)`` over 0 <= k < n in :func:`batch_threads` threads (the
    calling thread one of them): each takes the next piece of :data:`PIECES_PER_THREAD` per
    thread until none is left, so the work goes where it runs fastest and a batch is never
    held up by a thread on a busy core. The kernel must release the GIL and write only the
    rows of its range. (The caller works too, so a batch completes even when every pool thread
    serves another batch.)"""
    threads = batch_threads(n) if threads is None else max(1, int(threads))
    if threads == 1:
        kernel(*args, 0, n)
        return
    size = max(1, -(-n // (threads * PIECES_PER_THREAD)))
    starts = itertools.count(0, size)  # (next() on it is atomic under the GIL)

    def work() -> None:
        for start in starts:
            if start >= n:
                return
            kernel(*args, start, min(n, start + size))

    helpers = [_pool().submit(work) for _ in range(threads - 1)]
    work()
    for helper in helpers:
        helper.result()


def _number(name: str, value: Any) -> float:
    """``value`` as a float; anything else is an InvalidInputError naming ``name``."""
    if isinstance(value, bool):
        raise InvalidInputError(f"{name} must be a number, got {value!r}")
    try:
        return float(value)
    except (TypeError, ValueError):
        raise InvalidInputError(f"{name} must be a number, got {value!r}") from None


def compile_system(system: System | str, **parameters: float) -> CompiledSystem:
    """:class:`CompiledSystem` of a System, a library name or a system file."""
    return CompiledSystem(system, **parameters)


#: compiled_with's systems, by system and full parameter values (oldest first)
_WITH: dict[tuple[Any, tuple[tuple[str, float], ...]], CompiledSystem] = {}
#: how many parameter sets compiled_with keeps (each costs a parameter vector, not a compile)
WITH_CACHE_SIZE = 64


def compiled_with(system: System | str, parameters: Mapping[str, float] | None = None
                  ) -> CompiledSystem:
    """The compiled system of ``system`` (a System, a library name or a system file) with
    ``parameters`` (defaults for the rest): one object per process and parameter set, whose
    parameters never change afterwards, so threads may share it. Keyed by the full parameter
    values (``{"k": 27.0}`` and the defaults are one key); the least recently made of more than
    :data:`WITH_CACHE_SIZE` sets is dropped (a service's peers choose parameters)."""
    named = isinstance(system, (str, Path))
    ident: Any = str(system) if named else id(system)
    base = _WITH.get((ident, ()))
    if base is None or (not named and base.system is not system):
        base = CompiledSystem(system)
        with _LOCK:
            _WITH[(ident, ())] = base
    if not parameters:
        return base
    full = dict(base._defaults)
    full.update(parameters)  # (unknown names and bad values: CompiledSystem refuses them below)
    key = (ident, tuple(full.items()))
    try:
        found = _WITH.get(key)
    except TypeError:  # a value that is not a number: CompiledSystem says which
        return CompiledSystem(system, **parameters)
    if found is None:
        found = CompiledSystem(system, **parameters)
        with _LOCK:
            _WITH[key] = found
            while len(_WITH) > WITH_CACHE_SIZE:
                del _WITH[next(iter(_WITH))]
    return found


def simulate(system: System | str, maneuver: str, s: float, inputs: Any = None, *,
             parameters: dict[str, float] | None = None,
             options: SimulatorOptions = DEFAULT_OPTIONS,
             sample_dt: float | None = None) -> Trajectory:
    """``maneuver`` of ``system`` (a System, a library name or a system file) at s, with
    ``parameters`` (defaults for the rest): the compiled system of :func:`compiled_with`."""
    compiled = compiled_with(system, parameters)
    return compiled.simulate(maneuver, s, inputs, options=options, sample_dt=sample_dt)


def simulate_batch(system: System | str, maneuver: str, s: npt.ArrayLike,
                   inputs: npt.ArrayLike | None = None, *,
                   parameters: dict[str, float] | None = None,
                   options: SimulatorOptions = DEFAULT_OPTIONS) -> BatchResult:
    """:meth:`CompiledSystem.simulate_batch` of ``system`` (see :func:`simulate`)."""
    compiled = compiled_with(system, parameters)
    return compiled.simulate_batch(maneuver, s, inputs, options=options)


def kernels_cached(system: str) -> bool:
    """True when the compiled module of a library system or system file is on disk and Numba's
    cache holds its compiled functions and the shared kernel for the current sources (a start
    then loads them in about a second instead of compiling them)."""
    m = cached_module(system)
    if m is None:
        return False
    from biped_opt.codegen import kernel

    return all(fn.signatures or precompile.cached(fn, unknown=False)
               for fn in (kernel.simulate_maneuver, kernel.simulate_batch_kernel)) \
        and all(precompile.cached(getattr(m, name + "_c"), unknown=False)
                for name in abi.FUNCTIONS)


def warm_up(system: str) -> float:
    """Compile a system's simulation kernels now, or load them from Numba's on-disk cache,
    rather than inside the first call; returns the seconds it took. A node calls it before it
    offers its services, so that a client's first request is not held up by a compile longer
    than its timeout. (The values simulated are irrelevant: a kernel compiles per signature.)"""
    t0 = time.perf_counter()
    compiled = compiled_with(system)  # (the object later calls with the defaults use)
    maneuver = compiled.maneuvers[0]
    lo, hi = compiled.s_range(maneuver)
    mid = 0.5 * (lo + hi)
    compiled.simulate(maneuver, mid, None, sample_dt=0.05)  # the single-call kernel
    compiled.simulate_batch(maneuver, np.array([mid, mid]), None)  # the parallel one
    return time.perf_counter() - t0
