"""The node parameters every node reads the same way: one line naming the parameter when its
value is wrong, and the node stops with status 2 (:func:`biped_opt.nodes.run.run_node`)."""

from __future__ import annotations

from typing import Any

from biped_opt.errors import InvalidParameterError

__all__ = ["int_parameter", "float_parameter", "string_list_parameter"]


def int_parameter(node: Any, name: str, low: int) -> int:
    """The integer parameter ``name``, at least ``low``; else one error naming it (the node
    stops with status 2)."""
    value = node.get_parameter(name).value
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise InvalidParameterError(f"{name} must be an integer >= {low}, got {value!r}")
    return value


def float_parameter(node: Any, name: str) -> float:
    """The positive, finite number parameter ``name``; else one error naming it."""
    value = node.get_parameter(name).value
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not 0 < float(value) < float("inf"):
        raise InvalidParameterError(f"{name} must be a number > 0, got {value!r}")
    return float(value)


def string_list_parameter(node: Any, name: str) -> list[str]:
    """A list-of-strings parameter, also when given as one string in ROS 2's list syntax
    (``-p systems:=[rocking_bar, walker3]`` reaches a backend that reads no YAML as text)."""
    value = node.get_parameter(name).value
    if isinstance(value, str):
        import yaml

        text = value.strip()
        try:
            value = yaml.safe_load(text) if text.startswith("[") else [text] if text else []
        except yaml.YAMLError:
            raise InvalidParameterError(f"{name}: not a list: {value!r}") from None
    if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) for v in value):
        raise InvalidParameterError(f"{name} must be a list of strings, got {value!r}")
    return [v.strip() for v in value if v.strip()]
