"""argparse converters and output-path checks shared by the sub-commands: each error names
its argument."""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Callable
from pathlib import Path

from biped_opt.errors import InvalidInputError

__all__ = ["assignment", "finite_float", "input_file", "int_at_least", "int_in_range",
           "new_directory", "output_directory", "output_file", "positive_float"]


def finite_float(name: str) -> Callable[[str], float]:
    """A finite float; the error names the argument."""

    def convert(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a number, got {text!r}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{name} must be finite, got {text!r}")
        return value

    convert.__name__ = name
    return convert


def int_at_least(name: str, minimum: int) -> Callable[[str], int]:
    """An integer >= minimum; the error names the argument."""

    def convert(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be an integer, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"{name} must be at least {minimum}, got {value}")
        return value

    convert.__name__ = name
    return convert


def int_in_range(name: str, low: int, high: int) -> Callable[[str], int]:
    """An integer in [low, high]; the error names the argument and the range."""

    def convert(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be an integer, got {text!r}") from None
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(
                f"{name} must be between {low} and {high}, got {value}")
        return value

    convert.__name__ = name
    return convert


def positive_float(name: str, *, zero: bool = False) -> Callable[[str], float]:
    """A finite float > 0 (>= 0 with ``zero``); the error names the argument."""
    finite = finite_float(name)

    def convert(text: str) -> float:
        value = finite(text)
        if value < 0 or (value == 0 and not zero):
            bound = "at least 0" if zero else "positive"
            raise argparse.ArgumentTypeError(f"{name} must be {bound}, got {text!r}")
        return value

    convert.__name__ = name
    return convert


# -- output paths: checked before any work starts, so a typo costs no sweep ----------------

def _why(exc: OSError) -> str:
    return exc.strerror or type(exc).__name__


def output_directory(option: str, path: Path, *, create: bool = True) -> Path:
    """A directory to write results into: made with its parents when missing; an existing file
    in its place, or a place that cannot be created or written, is an error naming ``option``.

    ``create=False`` only checks (for a command that creates it once its inputs have been
    read): the nearest existing ancestor must be a writable directory."""
    if path.exists() and not path.is_dir():
        raise InvalidInputError(f"{option}: {str(path)!r} exists and is not a directory")
    if not create:
        ancestor = path
        while not ancestor.exists():
            ancestor = ancestor.parent
        if not ancestor.is_dir():
            raise InvalidInputError(f"{option}: cannot create directory {str(path)!r}: "
                                    f"{str(ancestor)!r} is not a directory")
        if not os.access(ancestor, os.W_OK | os.X_OK):
            raise InvalidInputError(f"{option}: cannot create directory {str(path)!r}: "
                                    f"{str(ancestor)!r} is not writable")
        return path
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InvalidInputError(f"{option}: cannot create directory {str(path)!r}: "
                                f"{_why(exc)}") from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise InvalidInputError(f"{option}: directory {str(path)!r} is not writable")
    return path


def output_file(option: str, path: Path, *, overwrite: bool) -> Path:
    """A file about to be written: its directory must exist and be writable (a missing one is
    most often a typo; nothing is created behind the user's back); a directory in its place
    is an error, and so is an existing file unless ``overwrite``."""
    parent = path.parent if str(path.parent) else Path(".")
    if path.is_dir():
        raise InvalidInputError(f"{option}: {str(path)!r} is a directory")
    if path.exists() and not overwrite:
        raise InvalidInputError(f"{option}: {str(path)!r} exists (remove it or choose another "
                                "name; a recording is never overwritten)")
    if not parent.is_dir():
        raise InvalidInputError(f"{option}: directory {str(parent)!r} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise InvalidInputError(f"{option}: directory {str(parent)!r} is not writable")
    return path


def new_directory(option: str, path: Path) -> Path:
    """A directory that a tool will create (a rosbag2 bag): it must not exist, or be empty; its
    parent must exist and be writable."""
    if path.exists():
        if not path.is_dir():
            raise InvalidInputError(f"{option}: {str(path)!r} exists and is not a directory")
        if any(path.iterdir()):
            raise InvalidInputError(f"{option}: directory {str(path)!r} is not empty")
        return path
    output_file(option, path, overwrite=False)
    return path


def input_file(option: str, path: Path) -> Path:
    """A file to read: it must exist and be a readable file."""
    if not path.exists():
        raise InvalidInputError(f"{option}: no such file {str(path)!r}")
    if not path.is_file():
        raise InvalidInputError(f"{option}: {str(path)!r} is not a file")
    if not os.access(path, os.R_OK):
        raise InvalidInputError(f"{option}: {str(path)!r} is not readable")
    return path


def assignment(option: str) -> Callable[[str], tuple[str, float]]:
    """NAME=VALUE with a finite number; the error names the option."""
    number = finite_float(option)

    def convert(text: str) -> tuple[str, float]:
        name, sep, value = text.partition("=")
        if not sep or not name.strip():
            raise argparse.ArgumentTypeError(f"{option} must look like NAME=VALUE, got {text!r}")
        return name.strip(), number(value)

    convert.__name__ = option
    return convert
