"""The ROS 2 nodes of biped_opt: simulator, optimiser and recorder (one module per executable).

Nodes stay thin: message -> conversion (:mod:`biped_opt.nodes.convert`) -> core -> message. They
run unchanged on real rclpy and on the built-in Cyclone DDS backend (:mod:`biped_opt.ros`). What a
request may name is resolved by :mod:`biped_opt.nodes.sources` (library systems, or names in the
operator's ``system_paths``; never a path), and a new system compiles beside the service in
:mod:`biped_opt.nodes.compiler`. Below the nodes: :mod:`~biped_opt.nodes.parameters` (the
parameters every node reads alike), :mod:`~biped_opt.nodes.refusals` (what a refused request
says) and :mod:`~biped_opt.nodes.run` (every node's ``main``).
"""
