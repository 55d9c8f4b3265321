"""The asmonc_vision node graph for a full ROS 2 install (asmonc_vision/graph.py).

    ros2 launch asmonc_vision asmonc.launch.py bag:=/path/to/bag [rate:=1.0]
    ros2 launch asmonc_vision asmonc.launch.py live:=true     # cameras + serial compass
    ... params_file:=/path/to/overrides.yaml                  # applied after each node's own

Every node of the graph is started with its config/*.yaml and restarted (``respawn``)
if it dies; while the detector is down the alarm node says FAULT.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from asmonc_vision.graph import launch_entries


def _nodes(context):
    live = LaunchConfiguration('live').perform(context).lower() in ('true', '1', 'yes')
    extra = LaunchConfiguration('params_file').perform(context)
    config_dir = os.path.join(get_package_share_directory('asmonc_vision'), 'config')
    entries = launch_entries('live' if live else 'bag', config_dir,
                             bag=LaunchConfiguration('bag').perform(context),
                             rate=float(LaunchConfiguration('rate').perform(context)),
                             params_files=(extra,) if extra else ())
    return [Node(**e) for e in entries]


def generate_launch_description():
    return LaunchDescription([
        DeclareLaunchArgument('bag', default_value='', description='rosbag2 bag to replay'),
        DeclareLaunchArgument('rate', default_value='1.0', description='replay speed factor'),
        DeclareLaunchArgument('live', default_value='false',
                              description='true: the cameras and the serial compass, no bag'),
        DeclareLaunchArgument('params_file', default_value='',
                              description='a ros__parameters YAML applied after each node\'s own'),
        OpaqueFunction(function=_nodes),
    ])
