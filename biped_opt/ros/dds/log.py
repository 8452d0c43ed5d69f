"""rclpy's logger on :mod:`logging`: the console format, ``throttle_duration_sec`` and ``once``.

Node loggers write ``[LEVEL] [time] [name]: message`` to stderr, independent of the
application's logging setup, as rclpy does. A call with ``throttle_duration_sec=T`` is logged at
most once every T seconds from the same call site (rclpy keys throttling by call site too); the
next line that gets through says how many were held back, so a flood of bad requests costs one
line a second and loses no count. Each logger (node) has its own budget per call site.
"""

from __future__ import annotations

import logging
import sys
import threading
import time
from typing import Any

__all__ = ["Logger", "LOG_PARENT"]

LOG_PARENT = "biped_opt.ros.nodes"


class _RosFormatter(logging.Formatter):
    """rclpy's console format: ``[INFO] [1700000000.123456789] [node]: message``."""

    def format(self, record: logging.LogRecord) -> str:
        level = {"WARNING": "WARN", "CRITICAL": "FATAL"}.get(record.levelname, record.levelname)
        name = record.name[len(LOG_PARENT) + 1:]
        return f"[{level}] [{record.created:.9f}] [{name}]: {record.getMessage()}"


class _StderrHandler(logging.Handler):
    """Writes to whatever ``sys.stderr`` is at emit time (redirections are honoured)."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            sys.stderr.write(self.format(record) + "\n")
            sys.stderr.flush()
        except Exception:  # never let logging break a callback
            self.handleError(record)


def _log_parent() -> logging.Logger:
    parent = logging.getLogger(LOG_PARENT)
    if not parent.handlers:
        # Like rclpy: INFO and above to stderr, independent of the application's logging setup.
        handler = _StderrHandler()
        handler.setFormatter(_RosFormatter())
        parent.addHandler(handler)
        parent.setLevel(logging.INFO)
        parent.propagate = False
    return parent


class _CallSites:
    """Per call site: when it last logged and how many calls it held back since."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._last: dict[tuple[str, str, int], float] = {}
        self._held: dict[tuple[str, str, int], int] = {}

    def clear(self) -> None:
        with self._lock:
            self._last.clear()
            self._held.clear()

    def admit(self, site: tuple[str, str, int], throttle: float | None, once: bool
              ) -> tuple[bool, int]:
        """(log it?, calls held back before it) for a call at ``site``."""
        now = time.monotonic()
        with self._lock:
            last = self._last.get(site)
            if last is not None and (once or (throttle is not None and now - last < throttle)):
                self._held[site] = self._held.get(site, 0) + 1
                return False, 0
            self._last[site] = now
            return True, self._held.pop(site, 0)


_SITES = _CallSites()


class Logger:
    """``rclpy`` logger subset (``debug`` ... ``fatal``, ``get_child``) with rclpy's keyword
    arguments ``throttle_duration_sec`` and ``once``."""

    def __init__(self, name: str) -> None:
        self.name = name
        self._log = _log_parent().getChild(name)

    def _emit(self, level: int, msg: str, throttle_duration_sec: float | None = None,
              once: bool = False, **_: Any) -> bool:
        if not self._log.isEnabledFor(level):
            return False
        if throttle_duration_sec is not None or once:
            caller = sys._getframe(2)
            site = (self.name, caller.f_code.co_filename, caller.f_lineno)
            admitted, held = _SITES.admit(site, throttle_duration_sec, once)
            if not admitted:
                return False
            if held:
                msg = f"{msg} ({held} more like this held back since the last one)"
        self._log.log(level, msg)
        return True

    def debug(self, msg: str, **kwargs: Any) -> bool:
        return self._emit(logging.DEBUG, msg, **kwargs)

    def info(self, msg: str, **kwargs: Any) -> bool:
        return self._emit(logging.INFO, msg, **kwargs)

    def warning(self, msg: str, **kwargs: Any) -> bool:
        return self._emit(logging.WARNING, msg, **kwargs)

    warn = warning

    def error(self, msg: str, **kwargs: Any) -> bool:
        return self._emit(logging.ERROR, msg, **kwargs)

    def fatal(self, msg: str, **kwargs: Any) -> bool:
        return self._emit(logging.CRITICAL, msg, **kwargs)

    def get_child(self, name: str) -> Logger:
        return Logger(f"{self.name}.{name}")
