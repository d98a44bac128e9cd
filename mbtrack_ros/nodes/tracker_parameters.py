"""The tracker_node parameters that configure the tracker, mapped to ``TrackerConfig`` fields.

Kept apart from :mod:`mbtrack_ros.nodes.params` (which imports rclpy) so that
``mbtrack replay --params`` reads a node parameter file without importing rclpy.
"""
from __future__ import annotations

__all__ = ['TRACKER_PARAMETERS']

#: tracker_node parameter -> (TrackerConfig field, type the node reads it as); the one map
#: from the node's names to the tracker's, also used by ``mbtrack replay --params``.
TRACKER_PARAMETERS: dict[str, tuple[str, type]] = {
    'tracker.algorithm': ('algorithm', str), 'tracker.particles': ('particles', int),
    'tracker.joint_particles': ('joint_particles', int), 'tracker.subsample': ('subsample', int),
    'tracker.pipeline_search': ('pipeline_search', bool), 'tracker.sigma': ('sigma', float),
    'tracker.d_occ': ('d_occ', float), 'tracker.mrf_radius': ('mrf_radius', float),
    'tracker.use_mrf': ('use_mrf', bool), 'tracker.release_time': ('release_time', float),
    'detection.threshold': ('detection_threshold', float),
    'detection.spare_support': ('spare_support', float),
    'detection.reuse_time': ('reuse_time', float),
    'detection.every': ('detection_every', int),
    'detection.adaptation_rate': ('adaptation_rate', float),
    'tracker.image_scale': ('image_scale', float),
}
