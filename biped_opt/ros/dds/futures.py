"""``rclpy.task.Future`` subset: a thread-safe result holder with done callbacks."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

__all__ = ["Future"]


class Future:
    """Result of an asynchronous call (``Client.call_async``)."""

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._done = False
        self._cancelled = False
        self._result: Any = None
        self._exception: BaseException | None = None
        self._callbacks: list[Callable[[Future], None]] = []

    def done(self) -> bool:
        return self._done

    def cancelled(self) -> bool:
        return self._cancelled

    def cancel(self) -> None:
        self._finish(cancelled=True)

    def result(self) -> Any:
        """The result (None until done); re-raises the exception set by the producer."""
        if self._exception is not None:
            raise self._exception
        return self._result

    def exception(self) -> BaseException | None:
        return self._exception

    def set_result(self, result: Any) -> None:
        self._finish(result=result)

    def set_exception(self, exception: BaseException) -> None:
        self._finish(exception=exception)

    def _finish(self, result: Any = None, exception: BaseException | None = None,
                cancelled: bool = False) -> None:
        with self._cond:
            if self._done:
                return
            self._result, self._exception, self._cancelled = result, exception, cancelled
            self._done = True
            callbacks, self._callbacks = self._callbacks, []
            self._cond.notify_all()
        for callback in callbacks:
            callback(self)

    def add_done_callback(self, callback: Callable[[Future], None]) -> None:
        with self._cond:
            if not self._done:
                self._callbacks.append(callback)
                return
        callback(self)

    def wait(self, timeout_sec: float | None = None) -> bool:
        """Block until done (another thread must be spinning); True when done."""
        with self._cond:
            return self._cond.wait_for(lambda: self._done, timeout_sec)
