"""Ctrl-C and SIGTERM as a request to stop, for the commands that run the ROS graph.

Python turns SIGINT into a KeyboardInterrupt raised wherever the main thread happens to be: in a
``print`` just after the "running" line, in the middle of finishing a file. A command that must
stop cleanly installs :func:`stop_requested` instead: both signals set an event and the command
decides where to stop. While it starts up (``interrupt=True``, until :meth:`StopRequest.defer`)
a signal still raises KeyboardInterrupt, so a long start (the first compile) can be abandoned.

The handler itself takes no lock. It runs in the main thread between two bytecodes, possibly
while that thread holds the very lock ``Event.set`` needs (inside ``Event.wait``, say), so it only
sets a flag and writes a byte to a pipe; a relay thread reading the pipe sets the event and calls
the deferred callback.
"""

from __future__ import annotations

import os
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
        self._signalled = False  # set by the handler (a plain store: no lock)
        self._on_stop: Callable[[], None] | None = None
        self._read_fd, self._write_fd = os.pipe()
        os.set_blocking(self._write_fd, False)
        self._relay = threading.Thread(target=self._relay_loop, name="stop-request", daemon=True)
        self._relay.start()

    def defer(self, on_stop: Callable[[], None] | None = None) -> None:
        """From now on a signal only sets the event and calls ``on_stop`` (from the relay thread;
        at once if a signal came already). ``on_stop`` must be thread-safe, e.g. set an event."""
        self._on_stop = on_stop
        self._interrupt = False
        if on_stop is not None and self.is_set():
            on_stop()

    def wait(self, timeout: float | None = None) -> bool:
        return self.event.wait(timeout)

    def is_set(self) -> bool:
        return self._signalled or self.event.is_set()

    def _handle(self, _signum: int, _frame: object) -> None:
        self._signalled = True
        try:
            os.write(self._write_fd, b"s")
        except BlockingIOError:  # (the pipe is full of earlier signals: the relay has work)
            pass
        if self._interrupt:
            raise KeyboardInterrupt

    def _relay_loop(self) -> None:
        while True:
            try:
                data = os.read(self._read_fd, 64)
            except OSError:
                return
            if b"s" in data:
                self.event.set()
                on_stop = self._on_stop
                if on_stop is not None and not self._interrupt:
                    on_stop()
            if not data or b"x" in data:  # (closed, or told to end)
                return

    def close(self) -> None:
        """End the relay thread (after the handlers are restored: no signal reaches it now)."""
        while True:
            try:
                os.write(self._write_fd, b"x")
                break
            except BlockingIOError:  # (full of signals not yet relayed: let it drain)
                self._relay.join(timeout=0.01)
        self._relay.join(timeout=5.0)
        os.close(self._write_fd)
        os.close(self._read_fd)


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
        request.close()
