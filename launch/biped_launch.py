"""Launch the biped_opt graph: simulator, optimiser and recorder with config/biped.yaml.

    ros2 launch biped_opt biped_launch.py
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch_ros.actions import Node

from launch import LaunchDescription


def generate_launch_description() -> LaunchDescription:
    config = os.path.join(get_package_share_directory("biped_opt"), "config", "biped.yaml")
    return LaunchDescription(
        [
            Node(package="biped_opt", executable=name, name=name, parameters=[config],
                 output="screen")
            for name in ("simulator", "optimiser", "recorder")
        ]
    )
