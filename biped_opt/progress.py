"""A one-line text progress bar that long computations report to (disabled: does nothing)."""

from __future__ import annotations

import math
import sys
import time
from typing import TextIO

__all__ = ["Progress", "bar"]


class Progress:
    """A one-line text progress bar, redrawn in place on ``stream`` (stderr by default).

    Disabled bars do nothing, so library code can always call :meth:`update`.
    """

    def __init__(self, total: int, label: str = "", *, stream: TextIO | None = None,
                 enabled: bool = True, width: int = 30, min_interval: float = 0.1) -> None:
        self.total = max(int(total), 1)
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = enabled
        self.width = width
        self.min_interval = min_interval
        self._last = -math.inf
        self._start = time.perf_counter()

    def update(self, done: int, total: int | None = None) -> None:
        if total is not None:
            self.total = max(int(total), 1)
        if not self.enabled:
            return
        now = time.perf_counter()
        if done < self.total and now - self._last < self.min_interval:
            return
        self._last = now
        filled = int(self.width * min(done, self.total) / self.total)
        bar = "#" * filled + "." * (self.width - filled)
        self.stream.write(
            f"\r{self.label} [{bar}] {done}/{self.total} {now - self._start:5.1f}s"
        )
        if done >= self.total:
            self.stream.write("\n")
        self.stream.flush()


def bar(progress: bool | Progress, total: int, label: str) -> Progress:
    if isinstance(progress, Progress):
        return progress
    return Progress(total, label, enabled=bool(progress))
