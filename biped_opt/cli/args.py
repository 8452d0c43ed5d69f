"""argparse converters shared by the sub-commands: each error names its argument."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

__all__ = ["finite_float", "int_at_least"]


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
