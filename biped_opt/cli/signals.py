"""Ctrl-C and SIGTERM as a request to stop, for the commands that run the ROS graph.

Python turns SIGINT into a KeyboardInterrupt raised wherever the main thread happens to be: in a
``print`` just after the "running" line, in the middle of finishing a file. A command that must
stop cleanly installs :func:`stop_requested` instead: both signals set an event and the command
decides where to stop. While it starts up (``interrupt=True``, until :meth:`StopRequest.defer`)
a signal still raises KeyboardInterrupt, so a long start (the first compile) can be abandoned.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

__all__ = ["StopRequest", "stop_requested"]

SIGNALS = (signal.SIGINT, signal.SIGTERM)


class StopRequest:
    """What a stop signal does: set :attr:`event`, call the deferred callback, and raise
    KeyboardInterrupt until :meth:`defer` is called (when made with ``interrupt=True``)."""

    def __init__(self, *, interrupt: bool) -> None:
        self.event = threading.Event()
        self._interrupt = interrupt
        self._on_stop: Callable[[], None] | None = None

    def defer(self, on_stop: Callable[[], None] | None = None) -> None:
        """From now on a signal only sets the event and calls ``on_stop`` (in the main thread,
        between two bytecodes of whatever it runs: it must be quick, e.g. set a flag)."""
        self._on_stop = on_stop
        self._interrupt = False

    def wait(self, timeout: float | None = None) -> bool:
        return self.event.wait(timeout)

    def is_set(self) -> bool:
        return self.event.is_set()

    def _handle(self, _signum: int, _frame: object) -> None:
        self.event.set()
        if self._interrupt:
            raise KeyboardInterrupt
        if self._on_stop is not None:
            self._on_stop()


@contextmanager
def stop_requested(*, interrupt: bool = False) -> Iterator[StopRequest]:
    """SIGINT and SIGTERM handled by a :class:`StopRequest` while the block runs; the previous
    handlers are restored afterwards."""
    request = StopRequest(interrupt=interrupt)
    previous = {sig: signal.signal(sig, request._handle) for sig in SIGNALS}
    try:
        yield request
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
