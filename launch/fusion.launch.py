"""Camera nodes and the fusion tracker on one host, or the part of them that runs here.

One host (every camera node and the tracker)::

    ros2 launch mbtrack_ros fusion.launch.py calibration_file:=room/calibration.yaml \
        cameras:=cam0,cam1,cam2,cam3,cam4

Several hosts: a hosts file names each host's cameras and the host of the tracker, and the
same command runs on every host; each starts its own group (``host`` defaults to the
machine's name)::

    # hosts.yaml
    fusion: hostF              # the tracker_node (fusion) runs here
    hosts:
      hostA: [cam0, cam1]      # camera_node per camera, in namespace /<room>/<camera>
      hostB: [cam2, cam3, cam4]

    ros2 launch mbtrack_ros fusion.launch.py calibration_file:=... hosts_file:=hosts.yaml
    ros2 launch mbtrack_ros fusion.launch.py ... host:=hostA     # name another host

``room`` puts every node and topic of one room under ``/<room>`` (several rooms: one launch
per room, each with its calibration). ``params_file`` holds the tracker's parameters
(``input_mode`` is set to ``foreground`` here). Needs a full ROS 2 install (``launch``,
``launch_ros``).
"""
from __future__ import annotations

import socket

import yaml
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, GroupAction, OpaqueFunction
from launch_ros.actions import Node, PushRosNamespace


def _groups(context):
    arg = {k: context.launch_configurations[k] for k in (
        'calibration_file', 'cameras', 'hosts_file', 'host', 'room', 'params_file',
        'working_pixels', 'image_transport')}
    host = arg['host'] or socket.gethostname()
    if arg['hosts_file']:
        with open(arg['hosts_file'], encoding='utf-8') as f:
            doc = yaml.safe_load(f)
        hosts = doc.get('hosts') or {}
        cameras = [str(c) for c in hosts.get(host, [])]
        every = [str(c) for cams in hosts.values() for c in cams]
        fusion_here = str(doc.get('fusion', '')) == host
    else:  # one host: everything
        cameras = every = [c for c in arg['cameras'].split(',') if c]
        fusion_here = True
    room = arg['room']
    pixels = int(arg['working_pixels'])
    tracks = f'/{room}/tracker_node/tracks' if room else '/tracker_node/tracks'
    actions = []
    for cam in cameras:
        actions.append(GroupAction([PushRosNamespace(cam), Node(
            package='mbtrack_ros', executable='camera_node', name='camera_node',
            output='screen', parameters=[{
                'calibration_file': arg['calibration_file'], 'camera': cam,
                'image_transport': arg['image_transport'], 'tracker.working_pixels': pixels,
                'tracks_topic': tracks}])]))
    if fusion_here:
        params = [arg['params_file']] if arg['params_file'] else []
        prefix = f'/{room}' if room else ''
        topics = {'cameras': every}
        for cam in every:
            topics[f'camera.{cam}.image_topic'] = f'{prefix}/{cam}/working/image'
            topics[f'camera.{cam}.foreground_topic'] = f'{prefix}/{cam}/working/foreground'
        actions.append(Node(
            package='mbtrack_ros', executable='tracker_node', name='tracker_node',
            output='screen', parameters=params + [{
                'calibration_file': arg['calibration_file'], 'input_mode': 'foreground',
                'tracker.working_pixels': pixels, **topics}]))
    return [GroupAction([PushRosNamespace(room), *actions])] if room else actions


def generate_launch_description() -> LaunchDescription:
    args = [
        DeclareLaunchArgument('calibration_file', description='room calibration YAML'),
        DeclareLaunchArgument('cameras', default_value='',
                              description='one host: comma-separated camera names'),
        DeclareLaunchArgument('hosts_file', default_value='',
                              description='several hosts: host -> cameras, and the fusion '
                              'host (see the module docstring)'),
        DeclareLaunchArgument('host', default_value='',
                              description='this host in hosts_file (default: its name)'),
        DeclareLaunchArgument('room', default_value='',
                              description='namespace of this room (several rooms)'),
        DeclareLaunchArgument('params_file', default_value='',
                              description='tracker_node parameters YAML'),
        DeclareLaunchArgument('working_pixels', default_value='76800',
                              description='tracker.working_pixels of every node'),
        DeclareLaunchArgument('image_transport', default_value='raw',
                              description='raw | compressed: the cameras\' topics'),
    ]
    return LaunchDescription(args + [OpaqueFunction(function=_groups)])
