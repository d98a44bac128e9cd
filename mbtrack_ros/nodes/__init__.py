"""ROS 2 layer: message conversions, output messages, the tracker node and the bag player.

Every module here may import rclpy; nothing in :mod:`mbtrack_ros.core` imports from here.
"""
