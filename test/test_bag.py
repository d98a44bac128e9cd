"""rosbag2 recordings: written with rosbags, read back with rosbags and the mcap reader."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from mbtrack_ros.recording.bag import (
    GROUND_TRUTH_TOPIC, BagError, RecordingReader, RecordingWriter, camera_info_topic,
    image_topic, prefetched)
from mbtrack_ros.recording.csvfiles import GroundTruthRow

STAMP0 = 1_700_000_000 * 10**9
PERIOD = 66_666_667


def frames(room, n, rng):
    return [{name: rng.integers(0, 256, (cam.height, cam.width, 3), dtype=np.uint8)
             for name, cam in room.cameras.items()} for _ in range(n)]


def write(path, room, images, **kw):
    with RecordingWriter(path, room, **kw) as w:
        for i, ims in enumerate(images):
            w.write_frame(STAMP0 + i * PERIOD, ims)
            w.write_ground_truth(STAMP0 + i * PERIOD, [
                GroundTruthRow(STAMP0 + i * PERIOD, i, 7, 1.0 + i, 2.0, 1.75, False, ()),
                GroundTruthRow(STAMP0 + i * PERIOD, i, 9, 3.0, 2.5, 1.20, True, ())])


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_raw_round_trip(tmp_path, room, rng, storage):
    images = frames(room, 3, rng)
    write(tmp_path / 'bag', room, images, storage=storage)
    with RecordingReader(tmp_path / 'bag') as reader:
        assert reader.cameras == ['cam0', 'cam1']
        assert reader.frame_count == 3
        sets = list(reader.frames())
        assert [s.stamp_ns for s in sets] == [STAMP0 + i * PERIOD for i in range(3)]
        for fs, ims in zip(sets, images):
            assert not fs.missing and not fs.errors
            for name in ims:
                assert np.array_equal(fs.images[name], ims[name])
        gt = reader.ground_truth()
        assert [(r.frame, r.person_id, r.x, r.sitting) for r in gt[:2]] == \
            [(0, 7, 1.0, False), (0, 9, 3.0, True)]
        info = reader.camera_infos()['cam1']
        assert np.allclose(np.asarray(info.k).reshape(3, 3), room.cameras['cam1'].K)
        assert info.header.frame_id == room.cameras['cam1'].frame_id


def test_compressed_round_trip_and_recording_dir(tmp_path, room, rng):
    images = [{n: np.full((c.height, c.width, 3), (40 * i, 120, 200), np.uint8)
               for n, c in room.cameras.items()} for i in range(2)]
    write(tmp_path / 'rec' / 'bag', room, images, compressed=True, jpeg_quality=95)
    with RecordingReader(tmp_path / 'rec') as reader:  # a recording dir with bag/ inside
        assert image_topic('cam0', True) in reader.topics
        for fs, ims in zip(reader.frames(), images):
            for name in ims:
                assert np.abs(fs.images[name].astype(int) - ims[name]).max() <= 3


def test_mcap_reader_sees_documented_topics_and_types(tmp_path, room, rng):
    write(tmp_path / 'bag', room, frames(room, 2, rng))
    mcap_file = next(Path(tmp_path / 'bag').glob('*.mcap'))
    with mcap_file.open('rb') as handle:
        reader = make_reader(handle)
        summary = reader.get_summary()
        topics = {ch.topic: summary.schemas[ch.schema_id].name
                  for ch in summary.channels.values()}
        counts = {}
        for _, channel, message in reader.iter_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            assert message.log_time >= STAMP0
    assert topics == {
        image_topic('cam0'): 'sensor_msgs/msg/Image',
        image_topic('cam1'): 'sensor_msgs/msg/Image',
        camera_info_topic('cam0'): 'sensor_msgs/msg/CameraInfo',
        camera_info_topic('cam1'): 'sensor_msgs/msg/CameraInfo',
        GROUND_TRUTH_TOPIC: 'sensor_msgs/msg/PointCloud2',
    }
    assert counts[image_topic('cam0')] == 2 and counts[GROUND_TRUTH_TOPIC] == 2


def test_missing_camera_and_bad_paths(tmp_path, room, rng):
    write(tmp_path / 'bag', room, frames(room, 1, rng))
    with pytest.raises(BagError, match='no image topic for camera'):
        with RecordingReader(tmp_path / 'bag', cameras=['cam0', 'cam7']):
            pass
    with pytest.raises(BagError, match='not a rosbag2 directory'):
        RecordingReader(tmp_path / 'nothing')
    with pytest.raises(BagError, match='exists already'):
        RecordingWriter(tmp_path / 'bag', room)


def test_truncated_bag_raises_bag_error_after_good_frames(tmp_path, room, rng):
    # 24 frame sets of 115 kB span several of the writer's 1 MiB chunks
    write(tmp_path / 'bag', room, frames(room, 24, rng))
    mcap_file = next(Path(tmp_path / 'bag').glob('*.mcap'))
    data = mcap_file.read_bytes()
    mcap_file.write_bytes(data[: len(data) * 2 // 3])
    got = []
    with pytest.raises(BagError) as info:
        with RecordingReader(tmp_path / 'bag') as reader:
            for fs in reader.frames():
                got.append(fs.index)
    # the frame sets before the damage are delivered, then a one-line error says where
    assert got[:3] == [0, 1, 2]
    assert 'damaged' in str(info.value) and '\n' not in str(info.value)
    assert f'frame set {got[-1]}' in str(info.value)


def test_prefetched_reader_gives_the_same_frames_then_the_same_error(tmp_path, room, rng):
    """The reader thread of ``mbtrack replay``: every frame set before the damage, in order,
    with the same pixels, then the same BagError as reading directly."""
    write(tmp_path / 'bag', room, frames(room, 24, rng))
    mcap_file = next(Path(tmp_path / 'bag').glob('*.mcap'))
    data = mcap_file.read_bytes()
    mcap_file.write_bytes(data[: len(data) * 2 // 3])

    def read(wrap):
        got = []
        with pytest.raises(BagError) as info:
            with RecordingReader(tmp_path / 'bag') as reader:
                for fs in wrap(reader.frames()):
                    got.append(fs)
        return got, str(info.value)

    direct, direct_error = read(lambda it: it)
    ahead, ahead_error = read(lambda it: prefetched(it, depth=2))
    assert len(direct) >= 3 and ahead_error == direct_error
    assert [fs.index for fs in ahead] == [fs.index for fs in direct]
    assert [fs.stamp_ns for fs in ahead] == [fs.stamp_ns for fs in direct]
    for a, d in zip(ahead, direct):
        assert all(np.array_equal(a.images[c], d.images[c]) for c in d.images)


def test_prefetched_order_error_position_and_early_stop():
    def items():
        yield from range(5)
        raise ValueError('broken after 4')

    got = []
    with pytest.raises(ValueError, match='broken after 4'):
        for x in prefetched(items(), depth=1):
            got.append(x)
    assert got == [0, 1, 2, 3, 4]
    produced = []

    def counting():
        for i in range(1000):
            produced.append(i)
            yield i

    it = prefetched(counting(), depth=3)
    assert [next(it) for _ in range(2)] == [0, 1]
    it.close()  # the consumer stops: the thread stops too, a few items ahead at most
    assert len(produced) <= 2 + 3 + 2
    with pytest.raises(ValueError):
        next(prefetched([], depth=0))


def test_incomplete_sets_name_the_missing_camera(tmp_path, room, rng):
    ims = frames(room, 3, rng)
    ims[1] = {'cam0': ims[1]['cam0']}  # cam1 dropped a frame
    with RecordingWriter(tmp_path / 'bag', room) as w:
        for i, im in enumerate(ims):
            w.write_frame(STAMP0 + i * PERIOD, im)
    with RecordingReader(tmp_path / 'bag') as reader:
        sets = list(reader.frames())
    assert [s.missing for s in sets] == [[], ['cam1'], []]
    assert np.array_equal(sets[2].images['cam1'], ims[2]['cam1'])
