"""The Python processes this package starts, and how: a node's compile process, the second
compile process of a new system, the ahead-of-time build of a kernel.

``python -m module`` puts the working directory first on ``sys.path``, so a ``json.py`` (or any
module a child imports) in the folder a node or a command was started from - a shared or
temporary folder, a download folder - would run inside the child. Every child is therefore
started (:func:`popen`) with ``-P`` (Python 3.11 and later: no such entry, as
``PYTHONSAFEPATH``) and, whatever the Python, in a working directory of its own: an empty
directory this process created, readable by its user only (:func:`private_directory`), so that
on Python 3.10 the entry ``-m`` adds is that directory.

A build started in the background (``background=True``: the second compile process, the
ahead-of-time build) runs at a lower priority (nice +10), ends itself after
:data:`BACKGROUND_LIMIT_S` whatever it is doing (:func:`limit_background`, called by the
child), and is listed by :func:`running_in_background` until it ends, so that a command can
say what it leaves running when it exits.
"""

from __future__ import annotations

import atexit
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from typing import Any

__all__ = ["BACKGROUND_LIMIT_S", "BACKGROUND_NICE", "command", "popen", "private_directory",
           "background_mark", "running_in_background", "limit_background"]

#: the longest a background build runs [s]; it ends itself then (its cache entry stays absent,
#: so a later start builds it again)
BACKGROUND_LIMIT_S = 900.0
#: how much lower a background build's priority is (added to this process's niceness)
BACKGROUND_NICE = 10
#: the environment variable through which a child learns its time limit [s]
_LIMIT_ENV = "BIPED_OPT_BACKGROUND_LIMIT_S"

_DIRECTORY: list[str] = []
_BACKGROUND: list[tuple[str, subprocess.Popen[Any]]] = []
_LOCK = threading.Lock()


def private_directory() -> str:
    """An empty directory of this process's own (mode 0700, removed when it exits): the
    working directory of every child."""
    with _LOCK:
        if not _DIRECTORY:
            path = tempfile.mkdtemp(prefix="biped_opt-children-")
            _DIRECTORY.append(path)
            atexit.register(shutil.rmtree, path, ignore_errors=True)
        return _DIRECTORY[0]


def command(module: str, *args: str) -> list[str]:
    """``python [-P] -m module args...`` with this interpreter."""
    safe = ["-P"] if sys.version_info >= (3, 11) else []
    return [sys.executable, *safe, "-m", module, *args]


def popen(module: str, *args: str, background: str = "", **kwargs: Any) -> subprocess.Popen[Any]:
    """Start ``python -m module args...`` as described in the module docstring; ``kwargs`` go to
    :class:`subprocess.Popen` (``cwd`` is always :func:`private_directory`). ``background``:
    what the process builds, in a few words; it then runs niced, limited in time and listed
    by :func:`running_in_background`."""
    env = kwargs.pop("env", None)
    if background:
        env = {**(os.environ if env is None else env), _LIMIT_ENV: str(BACKGROUND_LIMIT_S)}
        kwargs["preexec_fn"] = _lower_priority
    process = subprocess.Popen(command(module, *args), cwd=private_directory(), env=env,
                               **kwargs)
    if background:
        with _LOCK:
            _BACKGROUND.append((background, process))
    return process


def _lower_priority() -> None:  # (in the child, before exec)
    try:
        os.nice(BACKGROUND_NICE)
    except OSError:
        pass


def background_mark() -> int:
    """How many background builds this process has started so far (for
    :func:`running_in_background`'s ``since``)."""
    with _LOCK:
        return len(_BACKGROUND)


def running_in_background(since: int = 0) -> list[str]:
    """What the background builds this process started (the ``since``-th and later: see
    :func:`background_mark`) and that still run are building."""
    with _LOCK:
        return [what for what, p in _BACKGROUND[since:] if p.poll() is None]


def limit_background(on_expiry: Any = None) -> None:
    """In a background build: move to a directory of this process's own (the starter's, its
    working directory so far, is removed when the starter exits, which a build outlives, and
    a compiler that looks up its working directory then fails), and end this process once the
    time its starter allowed (:data:`BACKGROUND_LIMIT_S`) has passed (a daemon thread;
    nothing when not limited), after calling ``on_expiry()`` (a lock file to remove)."""
    os.chdir(private_directory())
    text = os.environ.get(_LIMIT_ENV, "")
    try:
        limit = float(text)
    except ValueError:
        return
    if not limit > 0:
        return

    def watch() -> None:
        time.sleep(limit)
        try:
            if on_expiry is not None:
                on_expiry()
        finally:
            os._exit(4)

    threading.Thread(target=watch, name="background-limit", daemon=True).start()
