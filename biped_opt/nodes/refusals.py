"""What a node says when it cannot serve a request or prepare a system: one line for any failure
(:func:`failure_message`), the reply's message (:func:`refusal`), which failures a callback
answers (:func:`answers`) and the refused reply itself, logged (:func:`refuse`). A bad request
or a bug costs one request, never the node."""

from __future__ import annotations

import os
import re
import threading
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from biped_opt.errors import BipedOptError

__all__ = ["LOG_THROTTLE_S", "answers", "failure_message", "public", "refusal", "refuse"]

#: at most one log line per call site and this many seconds for rejected requests
LOG_THROTTLE_S = 1.0


def failure_message(exc: BaseException, what: str = "") -> str:
    """One line for any failure, also of the kinds that are not errors (SystemExit,
    KeyboardInterrupt raised by a system file's code), then prefixed by ``what``."""
    if isinstance(exc, BipedOptError):
        return str(exc)
    text = str(exc)
    line = f"{type(exc).__name__}{': ' + text if text else ''}"[:500]
    return f"{what}: {line}" if what else line


def answers(exc: BaseException) -> bool:
    """Whether a callback turns ``exc`` into a refused request: anything a request's code can
    raise (SystemExit and KeyboardInterrupt of a system file's code too), but not the
    KeyboardInterrupt of Ctrl-C or SIGTERM, which arrives on the main thread and stops the node."""
    return not (isinstance(exc, KeyboardInterrupt)
                and threading.current_thread() is threading.main_thread())


def refusal(exc: BaseException) -> str:
    """The reply's message for ``exc``: a :class:`BipedOptError` is a bad request (its message
    names the field); anything else (a bug, MemoryError, RecursionError, SystemExit of a system
    file's code) is ``internal error: ...``, one line."""
    message = failure_message(exc)
    return message if isinstance(exc, BipedOptError) else f"internal error: {message}"


#: an absolute path in a message: its directories, then its last part (kept)
_ABSOLUTE = re.compile(r"(?<![\w.~/])/(?:[^\s/'\"():;,]+/)+([^\s/'\"():;,]+)")


def public(message: str, private: Iterable[Path | str] = ()) -> str:
    """``message`` as a peer on the domain may read it: a file in one of the node's ``private``
    directories (system_paths, output_dir) named relative to it, any other absolute path by its
    last part. Where the node's files live is the operator's business, not the domain's."""
    for folder in sorted((str(p) for p in private), key=len, reverse=True):
        message = message.replace(folder.rstrip(os.sep) + os.sep, "")
    return _ABSOLUTE.sub(lambda match: match.group(1), message)


def refuse(node: Any, service: str, response: Any, exc: BaseException) -> Any:
    """``response`` as a refusal (:func:`refusal`: ``success = false`` and why, with no path
    of the node's in it: :func:`public`, the node's ``private_paths``): a bad request or a bug
    costs one request, not the node. Logged (with the paths), one line a second at most."""
    message = refusal(exc)
    if isinstance(exc, BipedOptError):
        node.get_logger().warning(f"rejected {service} request: {message}",
                                  throttle_duration_sec=LOG_THROTTLE_S)
    else:
        node.get_logger().error(f"{service} request failed: {message}",
                                throttle_duration_sec=LOG_THROTTLE_S)
    response.success = False
    response.message = public(message, getattr(node, "private_paths", ()))
    return response
