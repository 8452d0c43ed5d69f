"""A node for cross-process tests and benchmarks: serves OptimalPolicy, publishes BipedState.

Run: ``python -m tests.ros._echo_node --ros-args -p prefix:=/x`` (domain from ROS_DOMAIN_ID).
"""

from __future__ import annotations

import sys

from biped_opt import ros


class EchoNode(ros.Node):
    def __init__(self, **kwargs):
        super().__init__("echo", **kwargs)
        prefix = self.declare_parameter("prefix", "/echo").value
        self.pub = self.create_publisher(ros.msgs.BipedState, f"{prefix}/state", 10)
        self.srv = self.create_service(ros.srvs.OptimalPolicy, f"{prefix}/optimal_policy",
                                       self.on_request)

    def on_request(self, request, response):
        response.success = True
        response.message = request.maneuver
        response.value = 2.0 * request.theta0
        response.mode_sequence = [1, 3]
        state = ros.msgs.BipedState(maneuver=request.maneuver, theta0=request.theta0)
        self.pub.publish(state)
        return response


def main(args=None):
    ros.init(args=args)
    node = EchoNode()
    print("ready", flush=True)
    try:
        ros.spin(node)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        ros.try_shutdown()


if __name__ == "__main__":
    main(sys.argv)
