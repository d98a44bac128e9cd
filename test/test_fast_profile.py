"""Issue 5: the speed options: ``TrackerConfig.subsample`` is validated and reaches the
likelihood; ``mbtrack replay --params`` reads a tracker_node parameter file; the fast profile
(config/clear_room_fast.yaml) loads in the node and the replay."""
from __future__ import annotations

import os

import numpy as np
import pytest

os.environ.setdefault('ROS_DOMAIN_ID', str(100 + os.getpid() % 100))

import rclpy  # noqa: E402
from rclpy.context import Context  # noqa: E402

from conftest import REPO, make_room  # noqa: E402
from mbtrack_ros.core.tracker import Tracker, TrackerConfig, TrackerError  # noqa: E402
from mbtrack_ros.core.dynamics import MotionConfig  # noqa: E402
from mbtrack_ros.nodes.tracker_parameters import tracker_config_values  # noqa: E402

FAST = REPO / 'config' / 'clear_room_fast.yaml'
OFFLINE = REPO / 'config' / 'clear_room_offline.yaml'


def test_subsample_is_validated_and_reaches_the_likelihood():
    calibration = make_room()
    for bad in (0, -1, 1.5, True):
        with pytest.raises(TrackerError, match='subsample'):
            TrackerConfig(subsample=bad)
    tracker = Tracker(calibration, TrackerConfig(subsample=3))
    assert tracker.measurement.config.subsample == 3
    assert Tracker(calibration, TrackerConfig()).measurement.config.subsample == 1


@pytest.mark.parametrize('name,default', [('min_inside_share', 0.5),
                                          ('min_visible_share', 0.1)])
def test_camera_share_thresholds_are_validated_and_reach_the_likelihood(name, default):
    from mbtrack_ros.core.likelihood import LikelihoodConfig, LikelihoodError

    calibration = make_room()
    for bad in (-0.1, 1.5, True, 'half'):
        with pytest.raises(TrackerError, match=name):
            TrackerConfig(**{name: bad})
    for bad in (-0.1, 1.5):
        with pytest.raises(LikelihoodError, match=name):
            LikelihoodConfig(**{name: bad})
    tracker = Tracker(calibration, TrackerConfig(**{name: 0.3}))
    assert getattr(tracker.measurement.config, name) == 0.3
    assert getattr(Tracker(calibration, TrackerConfig()).measurement.config, name) == default


def test_motion_values_of_a_dict_reach_the_motion_config():
    assert TrackerConfig.from_dict({'motion': {'wall_stops': False}}).motion.wall_stops is False


def test_tracker_defaults_are_the_built_configs_own_defaults():
    """TrackerConfig repeats some defaults of the configs it builds (sigma, d_occ,
    min_inside_share, min_visible_share, the release times); a default tracker builds each
    of them equal to that config's own default, so changing one place alone fails here."""
    from mbtrack_ros.core.detection.manager import AutoDetectionConfig
    from mbtrack_ros.core.likelihood import LikelihoodConfig

    assert Tracker(make_room(320, 240), TrackerConfig()).measurement.config == LikelihoodConfig()
    assert TrackerConfig().detection_config() == AutoDetectionConfig()


def test_release_recover_time_is_validated_and_reaches_the_releaser():
    calibration = make_room()
    for bad in (-0.1, np.inf, True, '0.2'):
        with pytest.raises(TrackerError, match='release_recover_time'):
            TrackerConfig(release_recover_time=bad)
    config = TrackerConfig(detection=True, release_recover_time=0.5)
    assert Tracker(calibration, config).detection.releaser.config.recover_time == 0.5
    default = Tracker(calibration, TrackerConfig(detection=True))
    assert default.detection.releaser.config.recover_time == 0.2
    params = tracker_config_values({'tracker.release_recover_time': 0.0})
    assert TrackerConfig.from_dict(params).release_recover_time == 0.0

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
    assert config().mrf_radius == 0.3
    assert config('--mrf-radius', '0.4').mrf_radius == 0.4
    assert not config().motion.orientation_follows_velocity
    assert config('--paper-motion').motion.orientation_follows_velocity   # 000 §VI
    # 000 §VI-A: position and velocity only, no posture changes
    assert config().motion.sit_flip_rate > 0
    assert config('--paper-motion').motion.sit_flip_rate == 0.0
    # the node's motion.sit_flip_rate, and the one-camera config of 000 §VI sets it to 0
    params.write_text('tracker_node:\n  ros__parameters:\n    motion:\n'
                      '      sit_flip_rate: 0.2\n')
    assert config('--params', str(params)).motion.sit_flip_rate == 0.2
    lanz = REPO / 'config' / 'lanz_seq.yaml'
    assert config('--params', str(lanz)).motion == config('--paper-motion').motion
    # the node's motion.* parameters, and --paper-motion on top of the file's other values
    params.write_text('tracker_node:\n  ros__parameters:\n    motion:\n'
                      '      velocity_noise: 0.4\n      orientation_follows_velocity: true\n')
    assert config('--params', str(params)).motion == MotionConfig(
        velocity_noise=0.4, orientation_follows_velocity=True)
    params.write_text('tracker_node:\n  ros__parameters:\n    motion:\n      max_speed: 2\n')
    assert config('--params', str(params), '--paper-motion').motion == MotionConfig(
        max_speed=2.0, orientation_follows_velocity=True, sit_flip_rate=0.0)
    params.write_text('tracker_node:\n  ros__parameters:\n    tracker:\n      mrf_radius: 0.25\n')
    assert config('--params', str(params)).mrf_radius == 0.25
    assert config('--params', str(params), '--mrf-radius', '0.35').mrf_radius == 0.35
    assert config().detection_every == 1
    assert config('--detection-every', '3').detection_every == 3
    params.write_text('tracker_node:\n  ros__parameters:\n    detection:\n      every: 2\n')
    assert config('--params', str(params)).detection_every == 2
    assert config('--params', str(params), '--detection-every', '4').detection_every == 4
    # every tracker setting the node reads, the replay reads too (one map, TRACKER_PARAMETERS)
    params.write_text('tracker_node:\n  ros__parameters:\n    tracker:\n      release_time: 2.0\n'
                      '    detection:\n      spare_support: 0.4\n      beside_threshold: 2.5\n')
    both = config('--params', str(params))
    assert (both.release_time, both.spare_support, both.beside_threshold) == (2.0, 0.4, 2.5)
    assert both.detection_config().beside_threshold == 2.5


def test_replay_params_file_refuses_unknown_keys(tmp_path):
    from mbtrack_ros.commands.replay import tracker_values_from_params

    bad = tmp_path / 'bad.yaml'
    bad.write_text('tracker_node:\n  ros__parameters:\n    tracker:\n      subsampel: 2\n')
    with pytest.raises(TrackerError, match='subsampel'):
        tracker_values_from_params(bad)
    bad.write_text('tracker_node:\n  ros__parameters:\n    motion:\n      velocty_noise: 1\n')
    with pytest.raises(TrackerError, match='velocty_noise'):
        tracker_values_from_params(bad)
    bad.write_text('tracker_node:\n  ros__parameters:\n    tracker:\n      particles: "50"\n')
    with pytest.raises(TrackerError, match="tracker.particles: expected int, got '50'"):
        tracker_values_from_params(bad)
    bad.write_text('tracker_node:\n  ros__parameters:\n    motion:\n'
                   '      orientation_follows_velocity: 1\n')
    with pytest.raises(TrackerError, match='expected bool'):
        tracker_values_from_params(bad)
    with pytest.raises(TrackerError, match='not a tracker_node parameter file'):
        tracker_values_from_params(tmp_path / 'missing.yaml')


def test_fast_profile_is_the_default_with_half_the_particles():
    from mbtrack_ros.commands.replay import tracker_values_from_params

    fast = tracker_values_from_params(FAST)
    default = tracker_values_from_params(REPO / 'config' / 'clear_room.yaml')
    assert {k for k in fast.keys() | default.keys() if fast.get(k) != default.get(k)} == \
        {'particles'}
    assert fast['particles'] == default['particles'] // 2


def test_offline_profile_is_the_default_with_fewer_particles_sparse_detection_half_size():
    from mbtrack_ros.commands.replay import tracker_values_from_params

    offline = tracker_values_from_params(OFFLINE)
    default = tracker_values_from_params(REPO / 'config' / 'clear_room.yaml')
    assert {k for k in offline.keys() | default.keys()
            if offline.get(k) != default.get(k)} == {'particles', 'detection_every',
                                                      'working_pixels'}
    assert offline['particles'] < default['particles']
    assert offline['detection_every'] > default.get('detection_every', 1)
    assert offline['working_pixels'] < default.get('working_pixels', 76800)


@pytest.mark.parametrize('profile', [FAST, OFFLINE], ids=['fast', 'offline'])
def test_fast_profile_loads_in_the_node_and_the_replay(tmp_path, profile):
    import argparse

    from mbtrack_ros.commands import replay
    from mbtrack_ros.nodes.tracker_node import TrackerNode
    from mbtrack_ros.synth.room import default_room, make_calibration

    calib = tmp_path / 'calibration.yaml'
    make_calibration(default_room()).save(calib)
    context = Context()
    rclpy.init(context=context)
    try:
        node = TrackerNode(cli_args=['--ros-args', '--params-file', str(profile),
                                     '-p', f'calibration_file:={calib}', '-p', 'warm_up:=false'],
                           context=context, step_thread=False)
        try:
            node_config = node.tracker.config
        finally:
            node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    parser = argparse.ArgumentParser()
    replay.add_parser(parser.add_subparsers())
    replay_config = replay._config(parser.parse_args(
        ['replay', 'REC', '--out', str(tmp_path), '--params', str(profile)]))
    assert node_config.particles == replay_config.particles == 50
    assert node_config.subsample == replay_config.subsample == 1
    assert node_config.detection_every == replay_config.detection_every == \
        (1 if profile == FAST else 3)
    assert node_config.working_pixels == replay_config.working_pixels == \
        (76800 if profile == FAST else 19200)
