"""Issue 5: the speed options: ``TrackerConfig.subsample`` is validated and reaches the
likelihood; ``mbtrack replay --params`` reads a tracker_node parameter file."""
from __future__ import annotations

import pytest

from conftest import make_room
from mbtrack_ros.core.tracker import Tracker, TrackerConfig, TrackerError


def test_subsample_is_validated_and_reaches_the_likelihood():
    calibration = make_room()
    for bad in (0, -1, 1.5, True):
        with pytest.raises(TrackerError, match='subsample'):
            TrackerConfig(subsample=bad)
    tracker = Tracker(calibration, TrackerConfig(subsample=3))
    assert tracker.measurement.config.subsample == 3
    assert Tracker(calibration, TrackerConfig()).measurement.config.subsample == 1


def test_replay_options_beat_the_params_file(tmp_path):
    import argparse

    from mbtrack_ros.commands import replay

    parser = argparse.ArgumentParser()
    replay.add_parser(parser.add_subparsers())

    def config(*extra: str) -> TrackerConfig:
        return replay._config(parser.parse_args(['replay', 'REC', '--out', str(tmp_path),
                                                 *extra]))

    params = tmp_path / 'node.yaml'
    params.write_text('tracker_node:\n  ros__parameters:\n    tracker:\n      particles: 50\n'
                      '      subsample: 2\n      seed: 9\n    detection:\n      threshold: 1.5\n')
    assert config() == TrackerConfig(seed=0, detection=True)  # defaults unchanged
    fast = config('--params', str(params))
    assert (fast.particles, fast.subsample, fast.seed) == (50, 2, 0)  # --seed rules
    assert fast.detection_threshold == 1.5
    mixed = config('--params', str(params), '--particles', '70', '--seed', '3')
    assert (mixed.particles, mixed.subsample, mixed.seed) == (70, 2, 3)
    assert config('--subsample', '3').subsample == 3


def test_replay_params_file_refuses_unknown_keys(tmp_path):
    from mbtrack_ros.commands.replay import tracker_values_from_params

    bad = tmp_path / 'bad.yaml'
    bad.write_text('tracker_node:\n  ros__parameters:\n    tracker:\n      subsampel: 2\n')
    with pytest.raises(TrackerError, match='subsampel'):
        tracker_values_from_params(bad)
    with pytest.raises(TrackerError, match='not a tracker_node parameter file'):
        tracker_values_from_params(tmp_path / 'missing.yaml')
