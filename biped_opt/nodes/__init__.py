"""The ROS 2 nodes of biped_opt: simulator, optimiser and recorder (one module per executable).

Nodes stay thin: message -> conversion (:mod:`biped_opt.nodes.convert`) -> core -> message. They
run unchanged on real rclpy and on the built-in Cyclone DDS backend (:mod:`biped_opt.ros`).
"""
