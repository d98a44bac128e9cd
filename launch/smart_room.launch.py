"""Launch the smart-room tracker, optionally with a bag player feeding it.

    ros2 launch mbtrack_ros smart_room.launch.py \
        params_file:=<share>/config/clear_room.yaml \
        calibration_file:=recordings/clear-room/calibration.yaml \
        bag:=recordings/clear-room/bag rate:=1.0 use_sim_time:=true

With ``bag`` empty only the tracker starts (live cameras). Needs a full ROS 2 install
(``launch``, ``launch_ros``); it cannot run in the rclpy-wheels environment of the tests.
"""
from __future__ import annotations

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration, PythonExpression
from launch_ros.actions import Node


def generate_launch_description() -> LaunchDescription:
    share = get_package_share_directory('mbtrack_ros')
    params_file = LaunchConfiguration('params_file')
    calibration = LaunchConfiguration('calibration_file')
    bag = LaunchConfiguration('bag')
    use_sim_time = LaunchConfiguration('use_sim_time')
    args = [
        DeclareLaunchArgument('params_file',
                              default_value=os.path.join(share, 'config', 'clear_room.yaml'),
                              description='tracker_node parameters YAML'),
        DeclareLaunchArgument('calibration_file', default_value='',
                              description='room calibration (overrides the YAML if set)'),
        DeclareLaunchArgument('bag', default_value='',
                              description='rosbag2 directory to play; empty = live cameras'),
        DeclareLaunchArgument('rate', default_value='1.0', description='playback speed'),
        DeclareLaunchArgument('loop', default_value='false', description='loop the bag'),
        DeclareLaunchArgument('use_sim_time', default_value='false',
                              description='use /clock (true when playing a bag)'),
    ]
    overrides = {'use_sim_time': use_sim_time}
    calibration_given = IfCondition(PythonExpression(["'", calibration, "' != ''"]))
    calibration_default = IfCondition(PythonExpression(["'", calibration, "' == ''"]))
    # two variants so that an empty calibration_file argument keeps the YAML's value
    tracker = Node(
        package='mbtrack_ros', executable='tracker_node', name='tracker_node',
        output='screen', emulate_tty=True,
        parameters=[params_file, overrides, {'calibration_file': calibration}],
        condition=calibration_given)
    tracker_yaml_calibration = Node(
        package='mbtrack_ros', executable='tracker_node', name='tracker_node',
        output='screen', emulate_tty=True, parameters=[params_file, overrides],
        condition=calibration_default)
    player = Node(
        package='mbtrack_ros', executable='bag_player', name='bag_player', output='screen',
        parameters=[{'bag': bag, 'rate': LaunchConfiguration('rate'),
                     'loop': LaunchConfiguration('loop'), 'publish_clock': True}],
        condition=IfCondition(PythonExpression(["'", bag, "' != ''"])))
    return LaunchDescription(args + [tracker, tracker_yaml_calibration, player])
