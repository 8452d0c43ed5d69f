"""ROS 2 actions on the built-in backend: ``rclpy.action``'s ActionServer and ActionClient subset,
with rcl_action's conventions on the wire.

An action ``/a`` is three services and two topics (rmw_cyclonedds names them as any other:
``rq/a/_action/send_goalRequest`` ...):

- ``/a/_action/send_goal`` (``pkg/action/A_SendGoal``: goal id and goal; accepted and stamp),
- ``/a/_action/cancel_goal`` (``action_msgs/srv/CancelGoal``: a ``GoalInfo``; a return code and
  the goals now canceling; a zero id means every goal, a non-zero stamp every goal accepted at or
  before it),
- ``/a/_action/get_result`` (``pkg/action/A_GetResult``: goal id; status and result, answered
  once the goal has ended),
- ``/a/_action/feedback`` (``pkg/action/A_FeedbackMessage``: goal id and feedback),
- ``/a/_action/status`` (``action_msgs/msg/GoalStatusArray`` of the goals the server keeps;
  reliable, transient local, depth 1, so a late client sees the current state).

The server runs each accepted goal's ``execute_callback`` in a thread of its own (it may block,
as a study does, while the node's executor serves everything else) and keeps the last
:data:`KEPT_RESULTS` ended goals for ``get_result``.
"""

from __future__ import annotations

import enum
import threading
import uuid
from collections import OrderedDict
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from ..interfaces import ActionType, load_interfaces
from .futures import Future
from .qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from .services import Service

if TYPE_CHECKING:
    from .node import Node

__all__ = ["ActionServer", "ActionClient", "GoalResponse", "CancelResponse", "GoalStatus",
           "ServerGoalHandle", "ClientGoalHandle", "STATUS_QOS"]

#: rcl_action's status topic profile
STATUS_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: ended goals kept for get_result (the oldest forgotten first)
KEPT_RESULTS = 64


class GoalResponse(enum.Enum):
    REJECT = 1
    ACCEPT = 2


class CancelResponse(enum.Enum):
    REJECT = 1
    ACCEPT = 2


class GoalStatus(enum.IntEnum):
    """``action_msgs/msg/GoalStatus`` values."""

    UNKNOWN = 0
    ACCEPTED = 1
    EXECUTING = 2
    CANCELING = 3
    SUCCEEDED = 4
    CANCELED = 5
    ABORTED = 6


_ENDED = (GoalStatus.SUCCEEDED, GoalStatus.CANCELED, GoalStatus.ABORTED)


def _uuid_msg(raw: bytes) -> Any:
    return load_interfaces().message_class("unique_identifier_msgs/msg/UUID")(uuid=list(raw))


def _key(goal_id: Any) -> bytes:
    return bytes(goal_id.uuid)


def _stamp_ns(stamp: Any) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def _names(node: Node, action_name: str) -> dict[str, str]:
    base = node._resolve(action_name)
    return {k: f"{base}/_action/{k}"
            for k in ("send_goal", "cancel_goal", "get_result", "feedback", "status")}


class ServerGoalHandle:
    """One goal on the server: ``request`` (the goal), ``goal_id``, ``status``,
    ``is_active``, ``is_cancel_requested``, ``publish_feedback``, and the ends ``succeed``,
    ``abort``, ``canceled``."""

    def __init__(self, server: ActionServer, goal_id: Any, request: Any, stamp: Any) -> None:
        self._server, self.goal_id, self.request, self.stamp = server, goal_id, request, stamp
        self.status = GoalStatus.ACCEPTED
        self._waiting: list[tuple[Any, int]] = []  # get_result requests to answer at the end
        self.result: Any = None

    @property
    def is_active(self) -> bool:
        return self.status not in _ENDED

    @property
    def is_cancel_requested(self) -> bool:
        return self.status == GoalStatus.CANCELING

    def publish_feedback(self, feedback: Any) -> None:
        message = self._server.action_type.Impl.FeedbackMessage(goal_id=self.goal_id,
                                                                feedback=feedback)
        self._server._feedback.publish(message)

    def _end(self, status: GoalStatus) -> None:
        if not self.is_active:
            raise RuntimeError(f"goal already ended ({self.status.name})")
        self.status = status
        self._server._publish_status()

    def succeed(self) -> None:
        self._end(GoalStatus.SUCCEEDED)

    def abort(self) -> None:
        self._end(GoalStatus.ABORTED)

    def canceled(self) -> None:
        if not self.is_cancel_requested:
            raise RuntimeError("canceled(): no cancel was requested")
        self._end(GoalStatus.CANCELED)


class _ResultService(Service):
    """``get_result``: a request for a goal still running is answered when the goal ends and
    its execute callback has returned its result."""

    server: ActionServer

    def _handle(self, request: Any) -> None:
        publication = request.sample_info.publication_handle
        with self.server._lock:
            handle = self.server._goals.get(_key(request.body.goal_id))
            # a goal ends (abort, succeed) inside its execute callback and has its result only
            # when the callback returns: until then, a request waits (else it got an empty one)
            if handle is not None and (handle.is_active or handle.result is None):
                handle._waiting.append((request.header, publication))
                return
        self._reply(request.header, self.server._result_response(handle), publication)


class ActionServer:
    """``rclpy.action.ActionServer(node, action_type, action_name, execute_callback, *,
    goal_callback, cancel_callback, callback_group)`` (see the module docstring)."""

    def __init__(self, node: Node, action_type: ActionType, action_name: str,
                 execute_callback: Callable[[ServerGoalHandle], Any], *,
                 goal_callback: Callable[[Any], GoalResponse] | None = None,
                 cancel_callback: Callable[[ServerGoalHandle], CancelResponse] | None = None,
                 callback_group: Any = None, **_ignored: Any) -> None:
        self.node, self.action_type = node, action_type
        self.execute_callback = execute_callback
        self.goal_callback = goal_callback or (lambda goal: GoalResponse.ACCEPT)
        self.cancel_callback = cancel_callback or (lambda handle: CancelResponse.REJECT)
        self._lock = threading.RLock()
        self._goals: OrderedDict[bytes, ServerGoalHandle] = OrderedDict()
        impl = action_type.Impl
        names = _names(node, action_name)
        group = callback_group or node.default_callback_group
        self._feedback = node.create_publisher(impl.FeedbackMessage, names["feedback"], 10)
        self._status = node.create_publisher(impl.GoalStatusMessage, names["status"], STATUS_QOS)
        self._send_goal = node.create_service(impl.SendGoalService, names["send_goal"],
                                              self._on_send_goal, callback_group=group)
        self._cancel = node.create_service(impl.CancelGoalService, names["cancel_goal"],
                                           self._on_cancel, callback_group=group)
        node._check()
        self._result = node._add(_ResultService(
            node, impl.GetResultService, names["get_result"], lambda req, rsp: rsp,
            QoSProfile(), group))
        self._result.server = self
        self._publish_status()

    # -- goals -----------------------------------------------------------------------------
    def _on_send_goal(self, request: Any, response: Any) -> Any:
        key = _key(request.goal_id)
        response.stamp = self.node.get_clock().now().to_msg()
        with self._lock:
            duplicate = key in self._goals
        if duplicate or self.goal_callback(request.goal) != GoalResponse.ACCEPT:
            response.accepted = False
            return response
        handle = ServerGoalHandle(self, request.goal_id, request.goal, response.stamp)
        with self._lock:
            self._goals[key] = handle
        self._publish_status()
        response.accepted = True
        threading.Thread(target=self._execute, args=(handle,), daemon=True,
                         name=f"goal-{uuid.UUID(bytes=key)}").start()
        return response

    def _execute(self, handle: ServerGoalHandle) -> None:
        with self._lock:
            if handle.status == GoalStatus.ACCEPTED:
                handle.status = GoalStatus.EXECUTING
        self._publish_status()
        try:
            result = self.execute_callback(handle)
        except Exception as exc:  # a bug in the callback: the goal aborts, the server lives
            self.node.get_logger().error(f"action goal failed: {type(exc).__name__}: {exc}")
            result = None
        with self._lock:
            handle.result = result if result is not None else self.action_type.Result()
            if handle.is_active:
                self.node.get_logger().warning("goal state not set by the execute callback; "
                                               "it is aborted")
                handle.status = GoalStatus.ABORTED
            waiting, handle._waiting = handle._waiting, []
            while len(self._goals) > KEPT_RESULTS:
                oldest = next(iter(self._goals))
                if self._goals[oldest].is_active:
                    break
                del self._goals[oldest]
        self._publish_status()
        response = self._result_response(handle)
        for header, publication in waiting:
            self._result._reply(header, response, publication)

    def _result_response(self, handle: ServerGoalHandle | None) -> Any:
        response = self.action_type.Impl.GetResultService.Response()
        if handle is None:
            response.status = int(GoalStatus.UNKNOWN)
            return response
        response.status = int(handle.status)
        if handle.result is not None:
            response.result = handle.result
        return response

    # -- cancel ----------------------------------------------------------------------------
    def _on_cancel(self, request: Any, response: Any) -> Any:
        codes = self.action_type.Impl.CancelGoalService.Response
        key, stamp = _key(request.goal_info.goal_id), _stamp_ns(request.goal_info.stamp)
        every = not any(key)
        with self._lock:
            chosen = [h for k, h in self._goals.items()
                      if (every and stamp == 0) or (not every and k == key)
                      or (stamp and _stamp_ns(h.stamp) <= stamp)]
        if not every and not any(_key(h.goal_id) == key for h in chosen):
            response.return_code = codes.ERROR_UNKNOWN_GOAL_ID
            return response
        canceling = []
        for handle in chosen:
            if handle.is_active and (handle.is_cancel_requested or self.cancel_callback(handle)
                                     == CancelResponse.ACCEPT):
                with self._lock:
                    if handle.is_active:
                        handle.status = GoalStatus.CANCELING
                        canceling.append(handle)
        info = load_interfaces().message_class("action_msgs/msg/GoalInfo")
        response.goals_canceling = [info(goal_id=h.goal_id, stamp=h.stamp) for h in canceling]
        if canceling:
            response.return_code = codes.ERROR_NONE
            self._publish_status()
        elif chosen and not any(h.is_active for h in chosen):
            response.return_code = codes.ERROR_GOAL_TERMINATED
        else:
            response.return_code = codes.ERROR_REJECTED
        return response

    # -- status ----------------------------------------------------------------------------
    def _publish_status(self) -> None:
        ifc = load_interfaces()
        status_t = ifc.message_class("action_msgs/msg/GoalStatus")
        info_t = ifc.message_class("action_msgs/msg/GoalInfo")
        with self._lock:
            statuses = [status_t(goal_info=info_t(goal_id=h.goal_id, stamp=h.stamp),
                                 status=int(h.status)) for h in self._goals.values()]
        self._status.publish(self.action_type.Impl.GoalStatusMessage(status_list=statuses))

    def destroy(self) -> None:
        for entity in (self._send_goal, self._cancel, self._result, self._feedback,
                       self._status):
            self.node._destroy_entity(entity)


class ClientGoalHandle:
    """A goal sent by an :class:`ActionClient`: ``accepted``, ``goal_id``, ``status``,
    ``get_result_async()`` and ``cancel_goal_async()``."""

    def __init__(self, client: ActionClient, goal_id: Any, accepted: bool, stamp: Any) -> None:
        self._client, self.goal_id, self.accepted, self.stamp = client, goal_id, accepted, stamp
        self.status = GoalStatus.ACCEPTED if accepted else GoalStatus.UNKNOWN

    def get_result_async(self) -> Future:
        """Future of the ``GetResult`` response (``.status``, ``.result``)."""
        request = self._client.action_type.Impl.GetResultService.Request(goal_id=self.goal_id)
        return self._client._get_result.call_async(request)

    def cancel_goal_async(self) -> Future:
        """Future of the ``CancelGoal`` response (``.return_code``, ``.goals_canceling``)."""
        info = load_interfaces().message_class("action_msgs/msg/GoalInfo")
        request = self._client.action_type.Impl.CancelGoalService.Request(
            goal_info=info(goal_id=self.goal_id))
        return self._client._cancel.call_async(request)


class ActionClient:
    """``rclpy.action.ActionClient(node, action_type, action_name, *, callback_group)``:
    ``wait_for_server``, ``server_is_ready``, ``send_goal_async(goal, feedback_callback)``
    (a Future of a :class:`ClientGoalHandle`) and ``destroy``."""

    def __init__(self, node: Node, action_type: ActionType, action_name: str, *,
                 callback_group: Any = None, **_ignored: Any) -> None:
        self.node, self.action_type = node, action_type
        impl = action_type.Impl
        names = _names(node, action_name)
        group = callback_group or node.default_callback_group
        self._lock = threading.Lock()
        self._feedback_callbacks: dict[bytes, Callable[[Any], None]] = {}
        self._handles: dict[bytes, ClientGoalHandle] = {}
        self._send_goal = node.create_client(impl.SendGoalService, names["send_goal"],
                                             callback_group=group)
        self._cancel = node.create_client(impl.CancelGoalService, names["cancel_goal"],
                                          callback_group=group)
        self._get_result = node.create_client(impl.GetResultService, names["get_result"],
                                              callback_group=group)
        self._feedback = node.create_subscription(impl.FeedbackMessage, names["feedback"],
                                                  self._on_feedback, 10, callback_group=group)
        self._status = node.create_subscription(impl.GoalStatusMessage, names["status"],
                                                self._on_status, STATUS_QOS,
                                                callback_group=group)

    def server_is_ready(self) -> bool:
        return all(c.service_is_ready() for c in (self._send_goal, self._cancel,
                                                   self._get_result))

    def wait_for_server(self, timeout_sec: float | None = None) -> bool:
        return all(c.wait_for_service(timeout_sec) for c in (self._send_goal, self._cancel,
                                                              self._get_result))

    def send_goal_async(self, goal: Any, feedback_callback: Callable[[Any], None] | None = None,
                        goal_uuid: Any = None) -> Future:
        goal_id = goal_uuid or _uuid_msg(uuid.uuid4().bytes)
        key = _key(goal_id)
        if feedback_callback is not None:
            with self._lock:
                self._feedback_callbacks[key] = feedback_callback
        request = self.action_type.Impl.SendGoalService.Request(goal_id=goal_id, goal=goal)
        sent = self._send_goal.call_async(request)
        future = Future()

        def answered(reply: Future) -> None:
            if reply.cancelled() or reply.exception() is not None:
                future.set_exception(reply.exception() or RuntimeError("send_goal canceled"))
                return
            response = reply.result()
            handle = ClientGoalHandle(self, goal_id, bool(response.accepted), response.stamp)
            with self._lock:
                if handle.accepted:
                    self._handles[key] = handle
                else:
                    self._feedback_callbacks.pop(key, None)
            future.set_result(handle)

        sent.add_done_callback(answered)
        return future

    def _on_feedback(self, message: Any) -> None:
        with self._lock:
            callback = self._feedback_callbacks.get(_key(message.goal_id))
        if callback is not None:
            callback(message)

    def _on_status(self, message: Any) -> None:
        with self._lock:
            for status in message.status_list:
                key = _key(status.goal_info.goal_id)
                handle = self._handles.get(key)
                if handle is not None:
                    handle.status = GoalStatus(status.status)
                    if handle.status in _ENDED:
                        self._feedback_callbacks.pop(key, None)

    def destroy(self) -> None:
        for entity in (self._send_goal, self._cancel, self._get_result, self._feedback,
                       self._status):
            self.node._destroy_entity(entity)
