"""The command line's input side, shared by the sub-commands: argparse converters and output-path
checks (each error names its argument), the option groups that several commands take (the
maneuver, the biped's problem overrides, the th0 range and progress bar, any system's
``--system``/``--problem``/``--s``/``--input``/``--param``) and the one validated value each group
becomes (a maneuver, a problem, a grid, a compiled system).

With ``--system`` a maneuver is swept over its parameter s (--s, --s-min, --s-max), fixed inputs
are ``--input NAME=VALUE``, system parameters ``--param NAME=VALUE``, and an optimal-control
problem is one the system declares (``--problem NAME``, default: the one named like --maneuver)
or a problem file (``--problem FILE.yaml|FILE.py``, whose ``system`` key may replace --system).
The biped's own options (--theta0, --u1.., --theta-star, --alpha, --bounds, --fixed, --variant)
stay the biped's. Imports of the core happen where a value is built, not while the parser is.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import sys
import tempfile
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from biped_opt.errors import BipedOptError, InvalidInputError, InvalidParameterError

if TYPE_CHECKING:
    import numpy as np
    import numpy.typing as npt

    from biped_opt.control.problems import Problem
    from biped_opt.paper.biped import Maneuver
    from biped_opt.paper.problems import OptimalControlProblem
    from biped_opt.simulation.compiled import CompiledSystem

__all__ = ["BIPED_ONLY", "GRADIENT_EPS_VALUES", "GRADIENT_SAMPLE_COUNTS", "GRADIENT_SIGMAS",
           "MAX_POINTS", "MAX_SEED", "add_maneuver_argument",
           "add_problem_arguments", "add_progress_arguments", "add_range_arguments",
           "add_system_arguments", "assignment", "checked_theta0", "compiled_from_args",
           "finite_float", "float_in_range", "grid_from_args", "input_file", "int_in_range",
           "new_directory", "output_directory", "output_file", "parse_maneuver_arg", "path_arg",
           "positive_float", "problem_from_args", "problem_from_system_args",
           "progress_from_args", "s_grid_from_args", "SWEEP_NUM", "uses_system",
           "add_large_argument", "check_size", "check_s", "check_physical_args"]

#: the most grid points, samples or cases one command takes: a million fixed-input simulations
#: are about a minute, 8 MB per array; a larger number is a typo, not a study
MAX_POINTS = 1_000_000
#: grid points of a biped's or a system's sweep when --num is not given (sweep, nonsmooth)
SWEEP_NUM = {"fixed": 401, "optimal": 201}
#: the gradient study as ``gradients`` and ``demo`` run it (paper Sec. V-A): smoothing widths,
#: sample counts of the stochastic estimators, finite-difference steps
GRADIENT_SIGMAS = (0.003, 0.03)
GRADIENT_SAMPLE_COUNTS = (4, 64)
GRADIENT_EPS_VALUES = (0.02, 0.002)
#: seeds are taken in 0..2**32 - 1 (numpy's legacy range, and what every seed here needs)
MAX_SEED = 2**32 - 1


def _given(text: str, most: int = 40, head: int = 20) -> str:
    """A value as an error message shows it: cut to its first ``head`` characters when longer
    than ``most``, with its length, so the message stays one line."""
    return repr(text) if len(text) <= most else f"{text[:head]!r}... ({len(text)} characters)"


def finite_float(name: str) -> Callable[[str], float]:
    """A finite float; the error names the argument."""

    def convert(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a number, got {_given(text)}"
                                             ) from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{name} must be finite, got {_given(text)}")
        return value

    convert.__name__ = name
    return convert


def int_in_range(name: str, low: int, high: int | Callable[[], int]) -> Callable[[str], int]:
    """An integer in [low, high]; the error names the argument and the range. ``high`` may be
    a function, called when a value is converted (a limit kept in a module the parser should
    not import: building the parser stays fast)."""

    def convert(text: str) -> int:
        top = high() if callable(high) else high
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be an integer, got {_given(text)}"
                                             ) from None
        if not low <= value <= top:
            shown = str(value) if len(text) <= 40 else _given(text)
            raise argparse.ArgumentTypeError(
                f"{name} must be between {low} and {top}, got {shown}")
        return value

    convert.__name__ = name
    return convert


class LazyChoices(Sequence[str]):
    """An option's choices read by ``load`` only when the option is given or help is shown,
    so that building the parser does not import the module that defines them (give the
    option a ``metavar``: argparse formats choices as the metavar otherwise)."""

    def __init__(self, load: Callable[[], Iterable[str]]) -> None:
        self._load = load
        self._values: tuple[str, ...] | None = None

    def _get(self) -> tuple[str, ...]:
        if self._values is None:
            self._values = tuple(self._load())
        return self._values

    def __getitem__(self, index: Any) -> Any:
        return self._get()[index]

    def __len__(self) -> int:
        return len(self._get())

    def __contains__(self, value: object) -> bool:
        return value in self._get()

    def __iter__(self) -> Iterator[str]:
        return iter(self._get())


def float_in_range(name: str, low: float, high: float) -> Callable[[str], float]:
    """A finite float in [low, high]; the error names the argument and the range."""
    finite = finite_float(name)

    def convert(text: str) -> float:
        value = finite(text)
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(
                f"{name} must be between {low:g} and {high:g}, got {_given(text)}")
        return value

    convert.__name__ = name
    return convert


def positive_float(name: str, *, zero: bool = False,
                   maximum: float | None = None) -> Callable[[str], float]:
    """A finite float > 0 (>= 0 with ``zero``), at most ``maximum`` if given; the error names
    the argument and the bound."""
    finite = finite_float(name)

    def convert(text: str) -> float:
        value = finite(text)
        if value < 0 or (value == 0 and not zero):
            bound = "at least 0" if zero else "positive"
            raise argparse.ArgumentTypeError(f"{name} must be {bound}, got {_given(text)}")
        if maximum is not None and value > maximum:
            raise argparse.ArgumentTypeError(
                f"{name} must be at most {maximum:g}, got {_given(text)}")
        return value

    convert.__name__ = name
    return convert


# -- output paths: checked while the command line is parsed, so a typo costs no sweep ---------

#: a path longer than this is shown cut, with its length
_SHOWN = 200


def _why(exc: OSError | ValueError) -> str:
    return (exc.strerror if isinstance(exc, OSError) else None) or str(exc) or \
        type(exc).__name__


def _shown(path: Path) -> str:
    return _given(str(path), _SHOWN, 40)


def _cannot_create_in(directory: Path) -> str:
    """Why no file can be created in ``directory`` ("" if one can). os.access cannot tell: it
    says yes to root everywhere, /proc included; creating (and removing) an empty file can."""
    try:
        fd, name = tempfile.mkstemp(prefix=".biped-opt-", dir=directory)
    except (OSError, ValueError) as exc:
        return _why(exc)
    os.close(fd)
    os.unlink(name)
    return ""


def _checked(option: str, path: Path, check: Callable[[], Path]) -> Path:
    """``check()``, with what the file system raises (a name too long) as an error naming
    ``option``; a NUL byte, which no file name holds (and pathlib's tests answer False for),
    is one too."""
    if "\0" in str(path):
        raise InvalidInputError(f"{option}: {_shown(path)}: a file name holds no NUL byte")
    try:
        return check()
    except (OSError, ValueError) as exc:
        if isinstance(exc, InvalidInputError):
            raise
        raise InvalidInputError(f"{option}: {_shown(path)}: {_why(exc)}") from None


def output_directory(option: str, path: Path, *, create: bool = True) -> Path:
    """A directory to write results into: made with its parents when missing; an existing file
    in its place, or a place that cannot be created or written, is an error naming ``option``.

    ``create=False`` only checks (at parse time, or for a command that creates it once its
    inputs have been read): the directory, or else its nearest existing ancestor, must be a
    directory where a file can be created."""
    def check() -> Path:
        if path.exists() and not path.is_dir():
            raise InvalidInputError(f"{option}: {_shown(path)} exists and is not a directory")
        if not create:
            ancestor = path
            while not ancestor.exists():
                ancestor = ancestor.parent
            if not ancestor.is_dir():
                raise InvalidInputError(f"{option}: cannot create directory {_shown(path)}: "
                                        f"{_shown(ancestor)} is not a directory")
            why = _cannot_create_in(ancestor)
            if why and ancestor == path:
                raise InvalidInputError(f"{option}: directory {_shown(path)} is not writable "
                                        f"({why})")
            if why:
                raise InvalidInputError(f"{option}: cannot create directory {_shown(path)}: "
                                        f"{_shown(ancestor)} is not writable ({why})")
            return path
        try:
            path.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise InvalidInputError(f"{option}: cannot create directory {_shown(path)}: "
                                    f"{_why(exc)}") from None
        why = _cannot_create_in(path)
        if why:
            raise InvalidInputError(f"{option}: directory {_shown(path)} is not writable ({why})")
        return path

    return _checked(option, path, check)


def output_file(option: str, path: Path, *, overwrite: bool) -> Path:
    """A file about to be written: its directory must exist and take a new file (a missing one
    is most often a typo; nothing is created behind the user's back); a directory in its place
    is an error, and so is an existing file unless ``overwrite`` (then it must open for
    writing)."""
    def check() -> Path:
        parent = path.parent if str(path.parent) else Path(".")
        if path.is_dir():
            raise InvalidInputError(f"{option}: {_shown(path)} is a directory")
        if path.exists() and not overwrite:
            raise InvalidInputError(f"{option}: {_shown(path)} exists (remove it or choose "
                                    "another name; a recording is never overwritten)")
        if not parent.is_dir():
            raise InvalidInputError(f"{option}: directory {_shown(parent)} does not exist")
        if path.exists():
            try:  # (appending nothing changes nothing, not even the time of change)
                os.close(os.open(path, os.O_WRONLY | os.O_APPEND))
            except OSError as exc:
                raise InvalidInputError(f"{option}: {_shown(path)} cannot be written "
                                        f"({_why(exc)})") from None
            return path
        why = _cannot_create_in(parent)
        if why:
            raise InvalidInputError(f"{option}: directory {_shown(parent)} is not writable "
                                    f"({why})")
        return path

    return _checked(option, path, check)


def new_directory(option: str, path: Path) -> Path:
    """A directory that a tool will create (a rosbag2 bag): it must not exist, or be an empty
    directory that takes a file; else its parent must exist and take one."""
    def check() -> Path:
        if path.exists():
            if not path.is_dir():
                raise InvalidInputError(f"{option}: {_shown(path)} exists and is not a "
                                        "directory")
            if any(path.iterdir()):
                raise InvalidInputError(f"{option}: directory {_shown(path)} is not empty")
            why = _cannot_create_in(path)
            if why:
                raise InvalidInputError(f"{option}: directory {_shown(path)} is not writable "
                                        f"({why})")
            return path
        return output_file(option, path, overwrite=False)

    return _checked(option, path, check)


def input_file(option: str, path: Path) -> Path:
    """A file to read: it must exist and be a readable file."""
    def check() -> Path:
        if not path.exists():
            raise InvalidInputError(f"{option}: no such file {_shown(path)}")
        if not path.is_file():
            raise InvalidInputError(f"{option}: {_shown(path)} is not a file")
        if not os.access(path, os.R_OK):
            raise InvalidInputError(f"{option}: {_shown(path)} is not readable")
        return path

    return _checked(option, path, check)


def path_arg(check: Callable[..., Path], option: str, **options: Any) -> Callable[[str], Path]:
    """``check`` (:func:`output_file`, :func:`output_directory` with ``create=False``,
    :func:`new_directory`, :func:`input_file`) as an argparse type: the path is checked while
    the command line is parsed, before any work starts, and nothing is created."""
    if options.get("create", False):
        raise ValueError("path_arg: parsing creates nothing (create=False)")

    def convert(text: str) -> Path:
        try:
            return check(option, Path(text), **options)
        except InvalidInputError as exc:  # (argparse puts "argument OPTION: " in front)
            raise argparse.ArgumentTypeError(str(exc).removeprefix(f"{option}: ")) from None

    convert.__name__ = option
    return convert


def assignment(option: str) -> Callable[[str], tuple[str, float]]:
    """NAME=VALUE with a finite number; the error names the option."""
    number = finite_float(option)

    def convert(text: str) -> tuple[str, float]:
        name, sep, value = text.partition("=")
        if not sep or not name.strip():
            raise argparse.ArgumentTypeError(
                f"{option} must look like NAME=VALUE, got {_given(text)}")
        return name.strip(), number(value)

    convert.__name__ = option
    return convert


# -- the option groups several commands take, and the one value each becomes ----------------

def add_progress_arguments(p: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    """--progress / --no-progress (default: a bar when stderr is a terminal)."""
    p.add_argument("--progress", dest="progress", action="store_true", default=None,
                   help="draw a progress bar on stderr (default: when stderr is a terminal)")
    p.add_argument("--no-progress", dest="progress", action="store_false")


def progress_from_args(args: argparse.Namespace) -> bool:
    """Whether to draw a progress bar: --progress/--no-progress, else when stderr is a tty."""
    return sys.stderr.isatty() if args.progress is None else bool(args.progress)


def add_maneuver_argument(parser: argparse.ArgumentParser) -> None:
    """--maneuver: the paper's maneuver, or a maneuver of --system."""
    from biped_opt.paper.biped import Maneuver

    parser.add_argument(
        "--maneuver",
        type=str,
        metavar="{" + ",".join(m.value for m in Maneuver) + "}",
        help="which maneuver of the paper (Sec. IV), or of --system",
    )


def parse_maneuver_arg(text: str | None) -> Maneuver:
    """--maneuver as one of the paper's maneuvers; the error names the argument."""
    from biped_opt.paper.biped import parse_maneuver

    if text is None:
        raise InvalidInputError("--maneuver is required")
    try:
        return parse_maneuver(text)
    except InvalidInputError as exc:
        raise InvalidInputError(f"--maneuver: {exc}") from None


def checked_theta0(maneuver: Maneuver | str, value: float, option: str = "--theta0") -> float:
    """An initial pitch inside the maneuver's range; the error names ``option``."""
    from biped_opt.paper.biped import check_theta0

    try:
        return check_theta0(maneuver, value)
    except InvalidInputError as exc:
        raise InvalidInputError(f"{option}: {exc}") from None


def _input_assignment(name: str, pairs: bool) -> Callable[[str], tuple[str, tuple[float, ...]]]:
    """NAME=VALUE (NAME=LO,HI when ``pairs``) with NAME one of the biped's inputs; errors name
    the option."""
    from biped_opt.paper.biped import INPUT_NAMES

    def convert(text: str) -> tuple[str, tuple[float, ...]]:
        key, sep, rest = text.partition("=")
        key = key.strip()
        if not sep or key not in INPUT_NAMES:
            form = "NAME=LO,HI" if pairs else "NAME=VALUE"
            raise argparse.ArgumentTypeError(
                f"{name} must look like {form} with NAME one of {', '.join(INPUT_NAMES)}, "
                f"got {text!r}"
            )
        parts = rest.replace(":", ",").split(",") if pairs else [rest]
        if len(parts) != (2 if pairs else 1):
            raise argparse.ArgumentTypeError(f"{name} {key}: expected LO,HI, got {rest!r}")
        values = []
        for part in parts:
            try:
                value = float(part)
            except ValueError:
                raise argparse.ArgumentTypeError(
                    f"{name} {key}: {part!r} is not a number"
                ) from None
            if not math.isfinite(value):
                raise argparse.ArgumentTypeError(f"{name} {key}: must be finite, got {part!r}")
            values.append(value)
        return key, tuple(values)

    convert.__name__ = name
    return convert


def add_problem_arguments(p: argparse.ArgumentParser, *, variant: bool = True) -> None:
    """The options that select the biped's optimal-control problem and override MODEL.md
    Sec. 5's defaults: --maneuver, --variant, --theta-star, --alpha, --bounds, --fixed."""
    add_maneuver_argument(p)
    if variant:
        p.add_argument("--variant", action="store_true",
                       help="liftoff only: decide the single-stance forces u1, u2 in [0, 3] "
                            "with u12 = 0 (MODEL.md Sec. 6)")
    p.add_argument("--theta-star", type=finite_float("--theta-star"), default=None,
                   help="target outcome th* [rad] (default per problem)")
    p.add_argument("--alpha", action="append", default=[], metavar="NAME=VALUE",
                   type=_input_assignment("--alpha", pairs=False),
                   help="input weight of a decision, e.g. --alpha u1=3e-4 (repeatable)")
    p.add_argument("--bounds", action="append", default=[], metavar="NAME=LO,HI",
                   type=_input_assignment("--bounds", pairs=True),
                   help="bounds of a decision, e.g. --bounds u12=-0.5,0.5 (repeatable)")
    p.add_argument("--fixed", action="append", default=[], metavar="NAME=VALUE",
                   type=_input_assignment("--fixed", pairs=False),
                   help="value of a non-decision input, e.g. --fixed u2=3 (repeatable)")


def problem_from_args(args: argparse.Namespace) -> OptimalControlProblem:
    """The biped's problem named by --maneuver/--variant with the command line's overrides."""
    from biped_opt.paper.biped import INPUT_NAMES, Maneuver
    from biped_opt.paper.problems import get_problem

    maneuver = parse_maneuver_arg(args.maneuver)
    name = maneuver.value
    if getattr(args, "variant", False):
        if maneuver is not Maneuver.LIFTOFF:
            raise InvalidInputError("--variant: only the liftoff maneuver has a variant problem")
        name = "liftoff-variant"
    problem = get_problem(name)
    try:
        if args.theta_star is not None:
            problem = dataclasses.replace(problem, theta_star=args.theta_star)
        fixed = list(problem.fixed_inputs)
        for key, (value,) in args.fixed:
            if key in problem.decisions:
                raise InvalidInputError(
                    f"--fixed: {key} is a decision of the {problem.name} problem, not fixed"
                )
            fixed[INPUT_NAMES.index(key)] = value
        problem = dataclasses.replace(problem, fixed_inputs=tuple(fixed))
    except InvalidParameterError as exc:
        raise InvalidInputError(f"--theta-star/--fixed: {exc}") from None
    for option, items, apply in (
        ("--alpha", args.alpha, lambda pr, k, v: pr.with_alpha(k, v[0])),
        ("--bounds", args.bounds, lambda pr, k, v: pr.with_bounds(k, v[0], v[1])),
    ):
        for key, values in items:
            try:
                problem = apply(problem, key, values)
            except (InvalidInputError, InvalidParameterError) as exc:
                raise InvalidInputError(f"{option}: {exc}") from None
    return problem


def add_range_arguments(p: argparse.ArgumentParser, num_help: str) -> None:
    """The biped's th0 sweep: --theta0-min, --theta0-max, --num, and the progress bar."""
    p.add_argument("--theta0-min", type=finite_float("--theta0-min"), default=None,
                   help="smallest th0 [rad] (default: -limit of the maneuver)")
    p.add_argument("--theta0-max", type=finite_float("--theta0-max"), default=None,
                   help="largest th0 [rad] (default: +limit of the maneuver)")
    p.add_argument("--num", type=int_in_range("--num", 2, MAX_POINTS), default=None,
                   help=num_help)
    add_progress_arguments(p)


def grid_from_args(args: argparse.Namespace, maneuver: str,
                   default_num: int) -> npt.NDArray[np.float64]:
    """The th0 grid of --theta0-min/--theta0-max/--num (0 included)."""
    from biped_opt.paper.sweeps import sweep_grid

    for option, value in (("--theta0-min", args.theta0_min), ("--theta0-max", args.theta0_max)):
        if value is not None:
            checked_theta0(maneuver, value, option)
    if (args.theta0_min is not None and args.theta0_max is not None
            and not args.theta0_min < args.theta0_max):
        raise InvalidInputError(
            f"--theta0-min must be below --theta0-max, got {args.theta0_min} >= {args.theta0_max}"
        )
    return sweep_grid(maneuver, args.theta0_min, args.theta0_max,
                      args.num if args.num is not None else default_num)


#: the biped's options, refused alongside --system (name on the command line, attribute)
BIPED_ONLY = (("--theta0", "theta0"), ("--theta0-min", "theta0_min"),
              ("--theta0-max", "theta0_max"), ("--theta-star", "theta_star"),
              ("--alpha", "alpha"), ("--bounds", "bounds"), ("--fixed", "fixed"),
              ("--variant", "variant"), ("--u1", "u1"), ("--u2", "u2"), ("--u12", "u12"))


def add_system_arguments(p: argparse.ArgumentParser, *, point: bool = False,
                         sweep: bool = False, problem: bool = True) -> None:
    """The options of any system (see the module docstring)."""
    g = p.add_argument_group("any system (instead of the biped)")
    g.add_argument("--system", metavar="NAME|FILE.py",
                   help="a library system (biped, walkerN[_coupled|_decoupled], rocking_bar) or "
                        "a system file; see `biped-opt systems`")
    if problem:
        g.add_argument("--problem", metavar="NAME|FILE",
                       help="an optimal-control problem the system declares, or a problem file "
                            "(.yaml/.py; README 'Problems on any system')")
    if point:
        g.add_argument("--s", type=finite_float("--s"), help="the maneuver's parameter s")
    if sweep:
        g.add_argument("--s-min", type=finite_float("--s-min"), default=None,
                       help="smallest s (default: the maneuver's range)")
        g.add_argument("--s-max", type=finite_float("--s-max"), default=None,
                       help="largest s (default: the maneuver's range)")
    g.add_argument("--input", action="append", default=[], metavar="NAME=VALUE",
                   type=assignment("--input"), help="a fixed input of the system (repeatable)")
    g.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   type=assignment("--param"), help="a parameter of the system (repeatable)")
    add_large_argument(g)


def add_large_argument(p: Any) -> None:
    """``--large``: compile a system beyond the nodes' size limits (:func:`check_size`)."""
    from biped_opt.nodes.sources import MAX_COORDINATES, MAX_LEGS

    p.add_argument("--large", action="store_true",
                   help=f"compile a system beyond {MAX_LEGS} constraints or {MAX_COORDINATES} "
                        "coordinates (the nodes' limits; such a compile takes from tens of "
                        "seconds, solo12 and g1, to minutes)")


def check_size(args: argparse.Namespace, flag: str, spec: Any) -> None:
    """The command line compiles systems only as large as the nodes do by default (README
    "Who may ask what": ``max_legs``, ``max_coordinates``) unless ``--large`` is given: a
    library system by its name, before anything is built; a file or a described system by its
    description. One error naming ``flag`` and the flag that lifts the limit."""
    from biped_opt.nodes.sources import MAX_COORDINATES, MAX_LEGS

    if spec is None or spec == "" or getattr(args, "large", False):
        return
    name = getattr(spec, "name", None) or str(spec)
    size = None
    if isinstance(spec, (str, Path)):
        from biped_opt.simulation.compiled import cached_size

        # (compiled before: its size from the cache's index, nothing imported or run)
        size = cached_size(str(spec))
        if size is None:
            from biped_opt.systems.files import library_size

            size = library_size(str(spec))
    if size is None:
        if isinstance(spec, (str, Path)):
            from biped_opt.simulation.facts import describe

            try:
                spec = describe(str(spec))
            except BipedOptError as exc:
                raise InvalidInputError(f"{flag}: {exc}") from None
        size = (len(spec.constraints), len(spec.q))
    legs, coordinates = size
    if legs > MAX_LEGS or coordinates > MAX_COORDINATES:
        raise InvalidInputError(
            f"{flag}: {name} has {legs} constraints and {coordinates} coordinates; the command "
            f"line compiles at most {MAX_LEGS} and {MAX_COORDINATES}, as the nodes do (larger "
            "systems take longer to compile: solo12 and g1 tens of seconds, others minutes): add "
            "--large to compile it anyway")


def check_s(compiled: CompiledSystem, maneuver: str, flag: str, value: float | None) -> None:
    """``value`` of ``flag`` (--s, --s-min, --s-max) must lie in the range of s the maneuver
    declares valid, as the biped's --theta0 must."""
    if value is None:
        return
    lo, hi = compiled.s_range(maneuver)
    if not lo <= value <= hi:
        raise InvalidInputError(
            f"{flag}: s = {value:g} is outside the valid range [{lo:g}, {hi:g}] of the "
            f"{maneuver} maneuver of {compiled.name}")


def check_physical_args(args: argparse.Namespace, compiled: CompiledSystem, maneuver: str,
                        s: float | None = None) -> None:
    """With --param given: the values must make a mechanical system at the maneuver's start
    (:func:`biped_opt.systems.physical.check_physical`, at ``s`` or the range's centre)."""
    if not getattr(args, "param", None):
        return
    from biped_opt.systems.physical import check_physical

    if s is None:
        lo, hi = compiled.s_range(maneuver)
        s = (lo + hi) / 2
    try:
        check_physical(compiled.system, compiled.parameters, maneuver, s)
    except BipedOptError as exc:
        raise InvalidInputError(f"--param: {exc}") from None


def uses_system(args: argparse.Namespace) -> bool:
    """Whether the command line selects a system (else it is the biped's); an option of the
    other kind is an error naming it."""
    if getattr(args, "system", None) is not None or getattr(args, "problem", None) is not None:
        for flag, attr in BIPED_ONLY:
            value = getattr(args, attr, None)
            if value not in (None, False, []):
                raise InvalidInputError(
                    f"{flag}: the biped's option; with --system use --s, --s-min/--s-max, "
                    "--input NAME=VALUE, --param NAME=VALUE and --problem")
        return True
    for flag in ("s", "s_min", "s_max", "input", "param"):
        if getattr(args, flag, None) not in (None, []):
            raise InvalidInputError(f"--{flag.replace('_', '-')}: only with --system")
    return False


def problem_from_system_args(args: argparse.Namespace, *, required: bool = True) -> Problem | None:
    """The Problem of --system/--problem/--maneuver with --param overrides, or None."""
    from biped_opt.control.problems import load_problem
    from biped_opt.simulation.compiled import system_facts

    try:
        if args.problem is not None:
            problem = load_problem(args.problem, system=args.system)
        else:
            if args.maneuver is None:
                if not required:
                    return None
                raise InvalidInputError("--problem (or --maneuver naming one) is required")
            system = system_facts(args.system)
            if args.maneuver not in system.problems:
                if not required:
                    return None
                raise InvalidInputError(
                    f"--problem: {system.where()} declares no problem named like --maneuver "
                    f"{args.maneuver!r} (problems: {', '.join(system.problems) or 'none'}); "
                    "give --problem NAME or a problem file")
            check_size(args, "--system", args.system)
            problem = load_problem(args.maneuver, system=args.system)
        if args.system is not None and args.problem is not None and \
                Path(str(args.problem)).suffix in (".yaml", ".yml", ".py"):
            chosen = system_facts(args.system).name
            if problem.facts.name != chosen:
                raise InvalidInputError(
                    f"--problem: {args.problem} is a problem on {problem.facts.name}, "
                    f"not on --system {chosen}")
        check_size(args, "--problem" if args.problem is not None else "--system",
                   problem.system)
        if args.param:
            merged = {**dict(problem.parameters), **dict(args.param)}
            problem = dataclasses.replace(problem, parameters=tuple(merged.items()))
    except InvalidInputError:
        raise
    except BipedOptError as exc:
        raise InvalidInputError(f"--problem: {exc}") from None
    if args.maneuver is not None and args.maneuver != problem.maneuver:
        raise InvalidInputError(f"--maneuver {args.maneuver!r}: the problem {problem.name} is "
                                f"on maneuver {problem.maneuver!r}")
    if args.param or getattr(args, "s", None) is not None:
        from biped_opt.control.solve import compiled_for

        compiled = compiled_for(problem)
        check_s(compiled, problem.maneuver, "--s", getattr(args, "s", None))
        check_physical_args(args, compiled, problem.maneuver, getattr(args, "s", None))
    return problem


def compiled_from_args(args: argparse.Namespace) -> CompiledSystem:
    """The compiled --system with its --param values; --maneuver is required with it."""
    from biped_opt.simulation.compiled import CompiledSystem

    if args.system is None:
        raise InvalidInputError("--system is required")
    if args.maneuver is None:
        raise InvalidInputError("--maneuver is required")
    check_size(args, "--system", args.system)
    compiled = CompiledSystem(args.system, **dict(args.param))
    check_physical_args(args, compiled, args.maneuver, getattr(args, "s", None))
    return compiled


def s_grid_from_args(args: argparse.Namespace, compiled: CompiledSystem, maneuver: str,
                     num: int) -> npt.NDArray[np.float64]:
    """The s grid of --s-min/--s-max/--num (default ``num``) over the maneuver's range."""
    from biped_opt.analysis.nonsmooth import s_grid

    check_s(compiled, maneuver, "--s-min", args.s_min)
    check_s(compiled, maneuver, "--s-max", args.s_max)
    return s_grid(compiled, maneuver, args.num or num, args.s_min, args.s_max)
