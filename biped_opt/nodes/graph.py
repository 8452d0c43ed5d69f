"""The three nodes in one process, as ``launch/biped_launch.py`` starts them in a ROS install.

:class:`Graph` creates a context of its own (so tests and tools never share one), the simulator,
optimiser and recorder with parameters from a ROS 2 parameter file, and spins them with a
multi-threaded executor in a background thread. It is a context manager; ``close()`` finishes any
recording, destroys the nodes and shuts the context down.
"""

from __future__ import annotations

import threading
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from biped_opt import ros
from biped_opt.nodes.optimiser import OptimiserNode
from biped_opt.nodes.recorder import RecorderNode
from biped_opt.nodes.simulator import SimulatorNode
from biped_opt.ros.params_file import default_parameters_file, load_parameters

__all__ = ["Graph"]

#: longest wait for the executor thread to return (a callback still running) [s]
_STOP_TIMEOUT_S = 30.0


def _overrides(values: Mapping[str, Any]) -> list[Any]:
    return [ros.Parameter(name, value=value) for name, value in values.items()]


class Graph:
    """simulator + optimiser + recorder on one executor thread (see the module docstring).

    ``overrides`` maps a node name to parameter values that win over the file's.
    """

    def __init__(
        self,
        *,
        params_file: str | Path | None = None,
        overrides: Mapping[str, Mapping[str, Any]] | None = None,
        domain_id: int | None = None,
        threads: int = 4,
    ) -> None:
        path = Path(params_file) if params_file is not None else default_parameters_file()
        overrides = overrides or {}
        self.context = ros.Context()
        ros.init(args=[], context=self.context, domain_id=domain_id)
        nodes: dict[str, Any] = {}
        try:
            for name, cls in (("simulator", SimulatorNode), ("optimiser", OptimiserNode),
                              ("recorder", RecorderNode)):
                values = {**load_parameters(path, name), **overrides.get(name, {})}
                nodes[name] = cls(context=self.context, parameter_overrides=_overrides(values))
        except BaseException:
            for node in nodes.values():
                node.destroy_node()
            ros.try_shutdown(context=self.context)
            raise
        self.simulator: SimulatorNode = nodes["simulator"]
        self.optimiser: OptimiserNode = nodes["optimiser"]
        self.recorder: RecorderNode = nodes["recorder"]
        self.executor = ros.MultiThreadedExecutor(num_threads=threads, context=self.context)
        for node in nodes.values():
            self.executor.add_node(node)
        self._thread = threading.Thread(target=self._spin, name="biped_opt-graph", daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        try:
            self.executor.spin()
        except Exception as exc:  # a callback's error ends the spin: say so
            self.simulator.get_logger().error(f"executor stopped: {exc!r}")

    def close(self) -> None:
        """Finish any recording, stop the executor (its thread returns before anything is
        destroyed), destroy the nodes, shut the context down."""
        self.recorder.close()
        self.executor.shutdown(timeout_sec=_STOP_TIMEOUT_S)
        self._thread.join(_STOP_TIMEOUT_S)
        for node in (self.recorder, self.optimiser, self.simulator):
            node.destroy_node()
        ros.try_shutdown(context=self.context)

    def __enter__(self) -> Graph:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
