"""Built-in ROS 2 backend: the rclpy subset of biped_opt on Cyclone DDS (ROS.md Sec. 4).

Wire-compatible with rmw_cyclonedds_cpp (ROS.md Sec. 2), so its nodes, topics and services are
visible to and callable from a ROS 2 graph running Cyclone DDS.
"""

from __future__ import annotations

from .actions import ActionClient, ActionServer, CancelResponse, GoalResponse, GoalStatus
from .context import (
    Context,
    NotInitializedError,
    get_default_context,
    init,
    localhost_only,
    loopback_config,
    ok,
    shutdown,
    try_shutdown,
)
from .entities import Publisher, Subscription, Timer
from .executors import (
    Executor,
    MultiThreadedExecutor,
    SingleThreadedExecutor,
    spin,
    spin_once,
    spin_until_future_complete,
)
from .futures import Future
from .node import (
    Clock,
    InvalidParameterTypeException,
    MutuallyExclusiveCallbackGroup,
    Node,
    Parameter,
    ParameterNotDeclaredException,
    ReentrantCallbackGroup,
    RosArgumentError,
    Time,
    parse_ros_args,
)
from .qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_parameters,
    qos_profile_sensor_data,
    qos_profile_services_default,
    qos_profile_system_default,
)
from .services import Client, MalformedMessageError, Service

__all__ = [
    "ActionClient", "ActionServer", "CancelResponse", "GoalResponse", "GoalStatus",
    "Context", "NotInitializedError", "get_default_context", "init", "localhost_only",
    "loopback_config", "ok", "shutdown", "try_shutdown", "Executor", "MultiThreadedExecutor",
    "SingleThreadedExecutor", "spin", "spin_once", "spin_until_future_complete", "Future",
    "InvalidParameterTypeException", "RosArgumentError",
    "Client", "Clock", "MalformedMessageError", "MutuallyExclusiveCallbackGroup", "Node",
    "Parameter", "ParameterNotDeclaredException", "Publisher", "ReentrantCallbackGroup", "Service",
    "Subscription", "Time", "Timer", "parse_ros_args", "DurabilityPolicy", "HistoryPolicy",
    "QoSProfile", "ReliabilityPolicy", "qos_profile_parameters", "qos_profile_sensor_data",
    "qos_profile_services_default", "qos_profile_system_default",
]
