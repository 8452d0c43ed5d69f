"""argparse converters and output-path checks shared by the sub-commands: each error names
its argument."""

from __future__ import annotations

import argparse
import math
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from biped_opt.errors import InvalidInputError

__all__ = ["MAX_POINTS", "MAX_SEED", "assignment", "finite_float", "float_in_range",
           "input_file", "int_in_range", "new_directory", "output_directory", "output_file",
           "path_arg", "positive_float"]

#: the most grid points, samples or cases one command takes: a million fixed-input simulations
#: are about a minute, 8 MB per array; a larger number is a typo, not a study
MAX_POINTS = 1_000_000
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


def int_in_range(name: str, low: int, high: int) -> Callable[[str], int]:
    """An integer in [low, high]; the error names the argument and the range."""

    def convert(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be an integer, got {_given(text)}"
                                             ) from None
        if not low <= value <= high:
            shown = str(value) if len(text) <= 40 else _given(text)
            raise argparse.ArgumentTypeError(
                f"{name} must be between {low} and {high}, got {shown}")
        return value

    convert.__name__ = name
    return convert


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
