"""Files a user hands a command (a recording, a study, a parameter or problem file), opened so
that none can exhaust the process that reads it.

Only regular files are read: ``/dev/zero`` never ends, a FIFO blocks until a writer comes, a
directory or a socket is no file (:func:`open_regular` opens without blocking, then looks at
what it opened). Text is read only up to a stated size (:func:`read_text`), so a study or
parameter file of gigabytes is refused in one line instead of filling memory; a YAML document
(:func:`read_yaml`) that does not parse is one line too, naming the file, line and column.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from biped_opt.errors import BipedOptError

__all__ = ["InputFileError", "MAX_TEXT_BYTES", "open_regular", "read_text", "read_yaml"]

#: the largest text file (study, parameters, problem) read [bytes]
MAX_TEXT_BYTES = 16 << 20


class InputFileError(BipedOptError, OSError):
    """A file that cannot be read as given: missing, not a regular file, too large."""


_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISFIFO, "a FIFO"),
          (stat.S_ISSOCK, "a socket"))


def open_regular(path: str | Path) -> tuple[int, int]:
    """(descriptor, size) of ``path`` opened for reading, if it is a regular file (a symlink
    to one is one); the caller closes the descriptor. Opening never blocks (a FIFO)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOCTTY", 0))
    except FileNotFoundError:
        raise InputFileError(f"{path}: no such file") from None
    except OSError as exc:
        raise InputFileError(f"{path}: cannot read: {exc.strerror}") from None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            kind = next((name for test, name in _KINDS if test(info.st_mode)), "no file")
            raise InputFileError(f"{path}: is {kind}, not a regular file")
        os.set_blocking(fd, True)
    except BaseException:
        os.close(fd)
        raise
    return fd, info.st_size


def read_text(path: str | Path, *, limit: int = MAX_TEXT_BYTES, what: str = "file") -> str:
    """The UTF-8 text of the regular file ``path``, at most ``limit`` bytes; anything else is
    an :class:`InputFileError` naming the file (``what`` says what it was to be)."""
    fd, size = open_regular(path)
    with os.fdopen(fd, "rb") as fh:
        if size > limit:
            raise InputFileError(f"{path}: {size} bytes; a {what} may have at most {limit}")
        data = fh.read(limit + 1)
    if len(data) > limit:  # (it grew while it was read)
        raise InputFileError(f"{path}: more than {limit} bytes; a {what} may have at most {limit}")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputFileError(f"{path}: not UTF-8 text (byte {exc.start}: "
                             f"{data[exc.start:exc.start + 1]!r})") from None


def read_yaml(path: str | Path, *, limit: int = MAX_TEXT_BYTES, what: str = "file") -> object:
    """The YAML document of the regular file ``path`` (:func:`read_text`); anything the parser
    refuses is one line naming the file and, where the parser says, the line and column (also
    a nesting too deep, or an integer of more digits than Python converts)."""
    import yaml  # (a file format: only when a file is read)

    text = read_text(path, limit=limit, what=what)
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" line {mark.line + 1}, column {mark.column + 1}:" if mark is not None else ""
        problem = getattr(exc, "problem", None) or type(exc).__name__
        raise InputFileError(f"{path}:{where} not valid YAML ({problem})") from None
    except (ValueError, RecursionError) as exc:
        reason = str(exc).split(";")[0][:100]
        raise InputFileError(f"{path}: not valid YAML ({type(exc).__name__}: {reason})") from None
