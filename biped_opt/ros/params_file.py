"""ROS 2 parameter files (``node: ros__parameters: {...}``) read without ROS.

Nested mappings flatten to dotted names, as ROS 2 does (``touchdown: {theta_star: -0.1}`` is the
parameter ``touchdown.theta_star``). ``/**`` applies to every node.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from biped_opt.errors import InvalidParameterError

__all__ = ["load_parameters", "default_parameters_file"]


def default_parameters_file() -> Path:
    """config/biped.yaml of the source checkout or of the installed share directory."""
    parents = Path(__file__).resolve().parents
    # <checkout>/biped_opt/ros/params_file.py, or
    # <prefix>/lib/pythonX.Y/site-packages/biped_opt/ros/params_file.py
    candidates = [parents[2] / "config" / "biped.yaml"]
    if len(parents) > 5:
        candidates.append(parents[5] / "share" / "biped_opt" / "config" / "biped.yaml")
    for candidate in candidates:
        if candidate.is_file():
            return candidate
    raise InvalidParameterError("config/biped.yaml not found; pass --params-file")


def _flatten(prefix: str, value: Any, out: dict[str, Any]) -> None:
    if isinstance(value, dict):
        for key, sub in value.items():
            _flatten(f"{prefix}.{key}" if prefix else str(key), sub, out)
    else:
        out[prefix] = value


def load_parameters(path: str | Path, node_name: str) -> dict[str, Any]:
    """The parameters a file gives ``node_name`` (its own section over ``/**``)."""
    from biped_opt.input_files import InputFileError, read_yaml

    path = Path(path)
    try:
        data = read_yaml(path, what="parameter file")
    except InputFileError as exc:  # (one line naming the file, line and column)
        raise InvalidParameterError(f"cannot read parameter file {exc}") from None
    if not isinstance(data, dict):
        raise InvalidParameterError(f"{path}: expected a mapping of node names")
    out: dict[str, Any] = {}
    for key in ("/**", node_name, f"/{node_name}"):
        section = data.get(key) or {}
        params = section.get("ros__parameters", {}) if isinstance(section, dict) else {}
        if not isinstance(params, dict):
            raise InvalidParameterError(f"{path}: {key}.ros__parameters must be a mapping")
        _flatten("", params, out)
    return out
