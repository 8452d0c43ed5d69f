"""A system file named with its arguments: ``chain.py:links=5,feet=true`` (SYSTEMS.md Sec. 4),
or a robot's URDF with the importer's options: ``solo.urdf:contacts=FL_FOOT+FR_FOOT`` (Sec. 4a).

The text after the last ``.py:`` (or ``.urdf:``) is a comma-separated list of ``name=value``; a
value is read as an integer, else a finite number, else ``true``/``false``, else a word
(letters, digits, ``_``, ``-``, ``.``, and ``+`` and ``*`` for a URDF's lists of links and
patterns of joints). A ``.py`` file's factory ``make_system(**arguments)`` builds the system,
a ``.urdf`` file's options go to :func:`biped_opt.systems.urdf.system_from_urdf`. Parsing
needs neither SymPy nor the file, so the start index can key a cached start on it.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

from biped_opt.errors import InvalidInputError, quoted

__all__ = ["FileSpec", "parse_file_spec", "FACTORY", "SUFFIXES"]

#: the function a system file defines to take arguments
FACTORY = "make_system"
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_WORD = re.compile(r"^[A-Za-z0-9_.\-+*]+$")
_INT = re.compile(r"^[+-]?[0-9]+$")
#: at most this many arguments, each value at most this long (a spec is typed, not generated)
MAX_ARGUMENTS, MAX_VALUE = 32, 64

Value = int | float | bool | str


@dataclass(frozen=True)
class FileSpec:
    """A system file and the arguments its factory is called with (in the given order)."""

    path: Path
    arguments: tuple[tuple[str, Value], ...] = ()

    def key(self) -> str:
        """The arguments as text independent of their order and spelling (``links=5``)."""
        return ",".join(f"{k}={v!r}" for k, v in sorted(self.arguments))

    def __str__(self) -> str:
        if not self.arguments:
            return str(self.path)
        args = ",".join(f"{k}={str(v).lower() if isinstance(v, bool) else v}"
                        for k, v in self.arguments)
        return f"{self.path}:{args}"


def _value(name: str, text: str, spec: str) -> Value:
    if len(text) > MAX_VALUE:
        raise InvalidInputError(f"{quoted(spec)}: argument {name}: value longer than "
                                f"{MAX_VALUE} characters")
    if _INT.match(text):
        return int(text)
    try:
        number = float(text)
    except ValueError:
        pass
    else:
        if not math.isfinite(number):
            raise InvalidInputError(f"{quoted(spec)}: argument {name} must be finite, "
                                    f"got {text}")
        return number
    if text.lower() in ("true", "false"):
        return text.lower() == "true"
    if not _WORD.match(text):
        raise InvalidInputError(
            f"{quoted(spec)}: argument {name}: {quoted(text)} is not a number, true, false "
            "or a word")
    return text


#: the files a system may come from: a Python system file, a robot's URDF
SUFFIXES = (".py", ".urdf")


def parse_file_spec(spec: str | Path) -> FileSpec | None:
    """The file and arguments of ``spec`` (``x.py``, ``x.py:a=1,b=2``, ``x.urdf:base=fixed``),
    or None when it names no ``.py`` or ``.urdf`` file (a library system). A malformed argument
    list is an InvalidInputError."""
    text = str(spec)
    if text.endswith(SUFFIXES):
        return FileSpec(Path(text))
    at, suffix = max((text.rfind(f"{s}:"), s) for s in SUFFIXES)
    if at < 0:
        return None
    path, rest = text[: at + len(suffix)], text[at + len(suffix) + 1:]
    items = rest.split(",") if rest else []
    if len(items) > MAX_ARGUMENTS:
        raise InvalidInputError(f"{quoted(text)}: more than {MAX_ARGUMENTS} arguments")
    arguments: dict[str, Value] = {}
    for item in items:
        name, eq, value = item.partition("=")
        name = name.strip()
        if not eq or not _NAME.match(name):
            raise InvalidInputError(
                f"{quoted(text)}: arguments are name=value separated by commas, got "
                f"{quoted(item)}")
        if name in arguments:
            raise InvalidInputError(f"{quoted(text)}: argument {name} is given twice")
        arguments[name] = _value(name, value.strip(), text)
    return FileSpec(Path(path), tuple(arguments.items()))
