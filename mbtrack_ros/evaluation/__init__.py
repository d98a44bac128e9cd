"""Scoring of tracker output: CLEAR MOT (py-motmetrics), posterior-mass curves, plots, reports.

No ROS imports here; inputs are the CSV rows of :mod:`mbtrack_ros.recording.csvfiles` and the
particle file defined in :mod:`mbtrack_ros.evaluation.posterior`.
"""
from __future__ import annotations

from mbtrack_ros.evaluation.clear_mot import (
    ClearMotResult, PersonFrameMatches, PersonStats, SequenceTable, TrackStats, clear_mot,
    combine_results, evaluate_many)
from mbtrack_ros.evaluation.errors import EvaluationError
from mbtrack_ros.evaluation.posterior import (
    DEFAULT_DISTANCES, ParticleRecorder, ParticleSet, PosteriorMassResult, load_particles,
    posterior_mass, posterior_mass_curve, save_particles)
from mbtrack_ros.evaluation.report import (
    format_table, markdown_table, score_rows, write_report)

__all__ = [
    'DEFAULT_DISTANCES', 'ClearMotResult', 'EvaluationError', 'ParticleRecorder', 'ParticleSet',
    'PersonFrameMatches', 'PersonStats', 'PosteriorMassResult', 'SequenceTable', 'TrackStats',
    'clear_mot', 'combine_results', 'evaluate_many', 'load_particles', 'posterior_mass',
    'posterior_mass_curve', 'save_particles', 'format_table', 'markdown_table', 'score_rows',
    'write_report',
]
