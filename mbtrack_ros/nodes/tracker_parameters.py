"""The tracker_node parameters that configure the tracker, mapped to ``TrackerConfig`` fields.

Kept apart from :mod:`mbtrack_ros.nodes.params` (which imports rclpy) so that
``mbtrack replay --params`` reads a node parameter file without importing rclpy.
"""
from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from mbtrack_ros.core.tracker import TrackerError

__all__ = ['TRACKER_PARAMETERS', 'tracker_config_values']

#: tracker_node parameter -> (TrackerConfig field, type the node reads it as); the one map
#: from the node's names to the tracker's, also used by ``mbtrack replay --params``. A field
#: ``motion.<name>`` is a field of the tracker's ``MotionConfig``.
TRACKER_PARAMETERS: dict[str, tuple[str, type]] = {
    'tracker.algorithm': ('algorithm', str), 'tracker.particles': ('particles', int),
    'tracker.joint_particles': ('joint_particles', int), 'tracker.subsample': ('subsample', int),
    'tracker.pipeline_search': ('pipeline_search', bool), 'tracker.sigma': ('sigma', float),
    'tracker.d_occ': ('d_occ', float), 'tracker.mrf_radius': ('mrf_radius', float),
    'tracker.coverage_gain': ('coverage_gain', float),
    'tracker.min_inside_share': ('min_inside_share', float),
    'tracker.min_visible_share': ('min_visible_share', float),
    'tracker.use_mrf': ('use_mrf', bool), 'tracker.release_time': ('release_time', float),
    'tracker.release_recover_time': ('release_recover_time', float),
    'detection.threshold': ('detection_threshold', float),
    'detection.beside_threshold': ('beside_threshold', float),
    'detection.spare_support': ('spare_support', float),
    'detection.reuse_time': ('reuse_time', float),
    'detection.every': ('detection_every', int),
    'detection.adaptation_rate': ('adaptation_rate', float),
    'tracker.working_pixels': ('working_pixels', int),
    'motion.velocity_noise': ('motion.velocity_noise', float),
    'motion.position_noise': ('motion.position_noise', float),
    'motion.orientation_noise': ('motion.orientation_noise', float),
    'motion.max_speed': ('motion.max_speed', float),
    'motion.orientation_follows_velocity': ('motion.orientation_follows_velocity', bool),
    'motion.wall_stops': ('motion.wall_stops', bool),
    'motion.sit_flip_rate': ('motion.sit_flip_rate', float),
}


def tracker_config_values(parameters: Mapping[str, Any]) -> dict[str, Any]:
    """``TrackerConfig.from_dict`` values of node parameters (names of
    ``TRACKER_PARAMETERS``; others are ignored), the ``motion.*`` ones gathered into a
    ``motion`` dict.

    Raises:
        TrackerError: a value not of its parameter's type (an int is a float, nothing else
            converts: ``'0.5'`` or ``true`` for a number is refused, not guessed).
    """
    values: dict[str, Any] = {}
    for name, (field, kind) in TRACKER_PARAMETERS.items():
        if name not in parameters:
            continue
        value = parameters[name]
        allowed = (int, float) if kind is float else (kind,)
        if not isinstance(value, allowed) or (kind is not bool and isinstance(value, bool)):
            raise TrackerError(f'parameter {name}: expected {kind.__name__}, got {value!r}')
        value = kind(value)
        if field.startswith('motion.'):
            values.setdefault('motion', {})[field.removeprefix('motion.')] = value
        else:
            values[field] = value
    return values
