"""Errors raised by biped_opt.

Every error derives from :class:`BipedOptError`; each also derives from the built-in exception a
caller would naturally catch (``ValueError`` for bad input...). The library raises; the command-line
interface maps these to exit codes and a service maps them to ``success=False`` replies.
"""

from __future__ import annotations

__all__ = [
    "BipedOptError",
    "InvalidParameterError",
    "InvalidInputError",
    "SimulationError",
    "quoted",
]


class BipedOptError(Exception):
    """Root of every error biped_opt raises on purpose."""


class InvalidParameterError(BipedOptError, ValueError):
    """A model or problem parameter is out of its domain (negative mass, NaN stiffness...)."""


class InvalidInputError(BipedOptError, ValueError):
    """A simulation or optimisation argument is invalid (NaN angle, unknown maneuver...).

    The message names the offending argument.
    """


class SimulationError(BipedOptError, RuntimeError):
    """A simulation could not produce the requested result (see its ``status``)."""


def quoted(value: object, limit: int = 40) -> str:
    """``repr(value)`` for an error message, cut to about ``limit`` characters: a message must
    name what was wrong without echoing a megabyte that someone sent."""
    text = repr(value)
    if len(text) <= limit:
        return text
    size = f" ({len(value)} characters)" if isinstance(value, str) else ""
    return f"{text[:limit]}...{size}"
