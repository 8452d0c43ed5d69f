"""One import point for biped_opt's ROS 2 nodes: real rclpy, or the built-in Cyclone DDS backend.

``from biped_opt import ros`` gives the rclpy subset the nodes use (``ros.init``, ``ros.Node``,
``ros.spin``, executors, QoS profiles...) plus the interface types
``ros.msgs.BipedState``, ``ros.srvs.OptimalPolicy`` (with ``.Request``/``.Response``),
``ros.actions.Study`` (with ``.Goal``/``.Result``/``.Feedback``), the ROS 2 Simulation
Interfaces' types (``ros.sim_srvs.StepSimulation``...: the ``simulation_interfaces`` package's
with rclpy, the vendored definitions' on the built-in backend) and rclpy.action's
``ActionServer``, ``ActionClient``, ``GoalResponse``, ``CancelResponse``.
The backend is chosen once, at import:

- ``rclpy``: real rclpy and the built ``biped_opt_interfaces`` package are importable;
- ``dds``: the built-in backend (:mod:`biped_opt.ros.dds`) on PyPI ``cyclonedds``, which speaks
  rmw_cyclonedds' wire conventions and generates its types from ``msg_defs/`` at run time.

``BIPED_OPT_BACKEND=auto|rclpy|dds`` overrides the choice (``auto`` prefers rclpy).
"""

from __future__ import annotations

import importlib
import os
import types
from typing import Any

from biped_opt.errors import BipedOptError

__all__ = [
    "BACKEND", "BackendError", "msgs", "srvs", "actions", "std_msgs", "message_type",
    "SIM_PACKAGE", "sim_msgs", "sim_srvs", "sim_actions",
    "from_cdr",
    "ActionServer", "ActionClient", "GoalResponse", "CancelResponse",
    "init", "shutdown", "try_shutdown", "ok", "spin", "spin_once", "spin_until_future_complete",
    "Context", "Node", "Future", "Parameter", "SingleThreadedExecutor", "MultiThreadedExecutor",
    "MutuallyExclusiveCallbackGroup", "ReentrantCallbackGroup", "QoSProfile", "HistoryPolicy",
    "ReliabilityPolicy", "DurabilityPolicy", "qos_profile_sensor_data",
    "qos_profile_services_default", "qos_profile_system_default", "STARTUP_ERRORS",
]


#: the ROS 2 Simulation Interfaces package: ``ros.sim_msgs``, ``ros.sim_srvs`` and
#: ``ros.sim_actions`` are its types (None with rclpy when the package is not installed)
SIM_PACKAGE = "simulation_interfaces"


class BackendError(BipedOptError, ImportError):
    """The requested ROS backend cannot be imported."""


def _rclpy_available() -> bool:
    try:
        importlib.import_module("rclpy")
        importlib.import_module("biped_opt_interfaces.msg")
    except ImportError:
        return False
    return True


def _choose() -> str:
    wanted = os.environ.get("BIPED_OPT_BACKEND", "auto").strip().lower() or "auto"
    if wanted not in ("auto", "rclpy", "dds"):
        raise BackendError(f"BIPED_OPT_BACKEND must be auto, rclpy or dds, got {wanted!r}")
    if wanted == "dds":
        return "dds"
    if _rclpy_available():
        return "rclpy"
    if wanted == "rclpy":
        raise BackendError("BIPED_OPT_BACKEND=rclpy but rclpy or biped_opt_interfaces "
                           "cannot be imported (source the ROS setup and the built workspace)")
    return "dds"


BACKEND = _choose()

if BACKEND == "rclpy":
    import biped_opt_interfaces.action as actions  # type: ignore[import-not-found, no-redef]
    import biped_opt_interfaces.msg as msgs  # type: ignore[import-not-found, no-redef]
    import biped_opt_interfaces.srv as srvs  # type: ignore[import-not-found, no-redef]
    import std_msgs.msg as std_msgs  # type: ignore[import-not-found, no-redef]

    try:  # (the standard's package, when installed: the simulator's Simulation Interfaces)
        import simulation_interfaces.action as sim_actions  # type: ignore[import-not-found]
        import simulation_interfaces.msg as sim_msgs  # type: ignore[import-not-found]
        import simulation_interfaces.srv as sim_srvs  # type: ignore[import-not-found]
    except ImportError:
        sim_msgs = sim_srvs = sim_actions = None
    from rclpy import (  # type: ignore[import-not-found, no-redef]
        init,
        ok,
        shutdown,
        spin,
        spin_once,
        spin_until_future_complete,
        try_shutdown,
    )
    from rclpy.action import (  # type: ignore[import-not-found, no-redef]
        ActionClient,
        ActionServer,
        CancelResponse,
        GoalResponse,
    )
    from rclpy.callback_groups import (  # type: ignore[import-not-found, no-redef]
        MutuallyExclusiveCallbackGroup,
        ReentrantCallbackGroup,
    )
    from rclpy.context import Context  # type: ignore[import-not-found, no-redef]
    from rclpy.exceptions import (  # type: ignore[import-not-found]
        InvalidParameterTypeException as _InvalidType,
    )
    from rclpy.exceptions import ParameterException  # type: ignore[import-not-found]
    from rclpy.executors import (  # type: ignore[import-not-found, no-redef]
        MultiThreadedExecutor,
        SingleThreadedExecutor,
    )
    from rclpy.node import Node  # type: ignore[import-not-found, no-redef]
    from rclpy.parameter import Parameter  # type: ignore[import-not-found, no-redef]
    from rclpy.qos import (  # type: ignore[import-not-found, no-redef]
        DurabilityPolicy,
        HistoryPolicy,
        QoSProfile,
        ReliabilityPolicy,
        qos_profile_sensor_data,
        qos_profile_services_default,
        qos_profile_system_default,
    )
    from rclpy.task import Future  # type: ignore[import-not-found, no-redef]

    #: what a node's construction raises for a bad parameter or ``--ros-args`` (besides
    #: BipedOptError): a bad command line, reported in one line by ``nodes.run.run_node``
    STARTUP_ERRORS: tuple[type[BaseException], ...] = (BipedOptError, ParameterException,
                                                       _InvalidType)
else:
    from .dds import (
        ActionClient,
        ActionServer,
        CancelResponse,
        Context,
        DurabilityPolicy,
        Future,
        GoalResponse,
        HistoryPolicy,
        MultiThreadedExecutor,
        MutuallyExclusiveCallbackGroup,
        Node,
        Parameter,
        QoSProfile,
        ReentrantCallbackGroup,
        ReliabilityPolicy,
        SingleThreadedExecutor,
        init,
        ok,
        qos_profile_sensor_data,
        qos_profile_services_default,
        qos_profile_system_default,
        shutdown,
        spin,
        spin_once,
        spin_until_future_complete,
        try_shutdown,
    )
    from .interfaces import PACKAGE, load_interfaces

    #: the built-in backend's parameter and ``--ros-args`` errors are BipedOptErrors
    STARTUP_ERRORS = (BipedOptError,)

    _ifc = load_interfaces()

    def _package(pkg: str) -> tuple[types.SimpleNamespace, ...]:
        def short(names: Any) -> dict[str, Any]:
            return {name.rsplit("/", 1)[1]: value for name, value in names
                    if name.startswith(pkg + "/")}

        return (types.SimpleNamespace(**short(
                    (name, _ifc.message_class(name)) for name in _ifc.msg_names)),
                types.SimpleNamespace(**short(_ifc.services.items())),
                types.SimpleNamespace(**short(_ifc.actions.items())))

    msgs, srvs, actions = _package(PACKAGE)
    sim_msgs, sim_srvs, sim_actions = _package(SIM_PACKAGE)
    std_msgs = types.SimpleNamespace(Header=_ifc.message_class("std_msgs/msg/Header"))
    del _ifc, PACKAGE


def message_type(ros_name: str) -> type | None:
    """The message class of the ROS type ``pkg/msg/Name`` on this backend (the project's own
    and the standard ones: ``tf2_msgs/msg/TFMessage``, ``rosgraph_msgs/msg/Clock``...), or None
    if the backend does not know it."""
    parts = ros_name.split("/")
    if len(parts) != 3 or parts[1] != "msg":
        return None
    if BACKEND == "rclpy":
        try:
            return getattr(importlib.import_module(f"{parts[0]}.msg"), parts[2], None)
        except ImportError:
            return None
    from .interfaces import InterfaceError, load_interfaces

    try:
        return load_interfaces().message_class(ros_name)
    except InterfaceError:
        return None


def from_cdr(cls: type, data: bytes) -> object:
    """A message of class ``cls`` from its CDR bytes (with the 4-byte encapsulation header)."""
    if BACKEND == "rclpy":
        from rclpy.serialization import deserialize_message  # type: ignore[import-not-found]

        return deserialize_message(data, cls)
    return cls.deserialize(data)  # type: ignore[attr-defined]
