"""Data-association baselines of Rasmussen & Hager (004): Kalman filter, measurement
sampling, PDAF, JPDAF and the Joint Likelihood Filter (issue 7).

The algorithms are pure functions over arrays and likelihood callables; :mod:`.filters`
wraps them in the tracker's filter interface and registers ``'pdaf'``, ``'jpdaf'`` and
``'jlf'`` with :func:`mbtrack_ros.core.filters.register_filter` on import.
"""
from __future__ import annotations

from mbtrack_ros.core.association.filters import (
    AssociationConfig, JLFFilter, JPDAFFilter, PDAFFilter)
from mbtrack_ros.core.association.jlf import (
    JLFResult, best_orders, distinct_orders, jlf_measurement, silhouette_boxes)
from mbtrack_ros.core.association.jpdaf import (
    JPDAResult, enumerate_events, joint_measurements, jpdaf_probabilities, jpdaf_update)
from mbtrack_ros.core.association.kalman import AssociationError
from mbtrack_ros.core.association.pdaf import PDAResult, association_probabilities, pdaf_update
from mbtrack_ros.core.association.sampling import Measurements, measurement_sampling

__all__ = [
    'AssociationConfig', 'AssociationError', 'JLFFilter', 'JLFResult', 'JPDAFFilter',
    'PDAFFilter', 'JPDAResult', 'Measurements', 'PDAResult',
    'association_probabilities', 'best_orders', 'distinct_orders', 'enumerate_events',
    'jlf_measurement', 'joint_measurements', 'jpdaf_probabilities', 'jpdaf_update',
    'measurement_sampling', 'pdaf_update', 'silhouette_boxes',
]
