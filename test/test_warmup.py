"""Issue 5: the node's start-up warm-up runs the whole pipeline and leaves no trace."""
from __future__ import annotations

import os

import numpy as np
import pytest

os.environ.setdefault('ROS_DOMAIN_ID', str(100 + os.getpid() % 100))

from mbtrack_ros.core.tracker import Tracker, TrackerConfig  # noqa: E402
from mbtrack_ros.synth.generator import Synthesizer  # noqa: E402


def _summary(results) -> list:
    return [(r.stamp_ns, [(t.track_id, np.round(t.mean, 9).tolist()) for t in r.tracks])
            for r in results]


@pytest.fixture(scope='module')
def frames():
    """16 frame sets of the clear room (320x240, 5 cameras): people are found from frame 8."""
    synth = Synthesizer('clear-room', seed=0, frames=16)
    return synth.calibration, list(synth)


def test_warm_up_runs_the_whole_pipeline_and_changes_nothing(frames):
    from mbtrack_ros.nodes.warmup import warm_up

    calibration, data = frames
    config = TrackerConfig(detection=True, seed=0)

    def run() -> list:
        tracker = Tracker(calibration, config, rng=np.random.default_rng(0))
        return _summary(tracker.step(f.stamp_ns, f.images) for f in data)

    before = run()
    report = warm_up(config, ceiling=True)
    after = run()
    # the warm-up started and tracked people (so the acquisition and filter kernels ran)
    assert report.births >= 1 and report.max_tracks >= 1 and report.frames == 14
    assert after == before
    assert any(tracks for _, tracks in before)  # the comparison covers tracked frames


def test_node_warm_up_keeps_ids_and_outputs(frames, tmp_path, context):
    """A node that warmed up publishes what a node without warm-up publishes, ids from 1."""
    from mbtrack_ros.nodes.conversions import rgb_to_image
    from mbtrack_ros.nodes.messages import make_header
    from mbtrack_ros.nodes.tracker_node import TrackerNode

    calibration, data = frames
    calib = tmp_path / 'calibration.yaml'
    calibration.save(calib)
    outputs = {}
    for warm in (False, True):
        node = TrackerNode(cli_args=['--ros-args', '-p', f'calibration_file:={calib}',
                                     '-p', 'tracker.seed:=5',
                                     '-p', f'warm_up:={str(warm).lower()}'],
                           context=context, step_thread=False)
        results = []
        process = node.process

        def spy(fs, process=process, results=results):
            results.append(process(fs))
            return results[-1]

        node.process = spy
        try:
            for f in data:
                for cam, rgb in f.images.items():
                    frame_id = calibration.cameras[cam].frame_id
                    node._on_image(cam, rgb_to_image(rgb, make_header(f.stamp_ns, frame_id)))
                node.process_pending()
            node.flush()
        finally:
            node.destroy_node()
        outputs[warm] = _summary(results)
    assert len(outputs[True]) == len(data)
    assert outputs[True] == outputs[False]
    ids = sorted({tid for _, tracks in outputs[True] for tid, _ in tracks})
    assert ids and ids[0] == 1


def test_half_scale_warm_up_and_debug_image_at_the_camera_size(frames, tmp_path, context):
    """tracker.working_pixels 19200 (160x120): the warm-up's debug overlay and the node's
    debug image draw the tracker's half-size occlusion layers on full-size camera images."""
    from mbtrack_ros.nodes.tracker_node import TrackerNode
    from mbtrack_ros.nodes.warmup import warm_up

    report = warm_up(TrackerConfig(detection=True, seed=0, working_pixels=19200), ceiling=True)
    assert report.births >= 1
    calibration, data = frames
    calib = tmp_path / 'calibration.yaml'
    calibration.save(calib)
    node = TrackerNode(cli_args=['--ros-args', '-p', f'calibration_file:={calib}',
                                 '-p', 'tracker.seed:=5', '-p', 'tracker.working_pixels:=19200',
                                 '-p', 'warm_up:=false'], context=context, step_thread=False)
    try:
        assert node.tracker.config.working_pixels == 19200
        cam = node.calibration.cameras['cam0']
        assert node.tracker.calibration.cameras['cam0'].width == cam.width // 2
        result = None
        for f in data:
            result = node.tracker.step(f.stamp_ns, f.images)
            node.tracker.search()
        assert len(result.tracks) >= 2  # occlusion maps need two tracks
        image = node.debug_image('cam0', data[-1].images['cam0'], result)
        assert (image.width, image.height) == (cam.width, cam.height)
    finally:
        node.destroy_node()
