"""Indexed MCAP files read in place (``recording/mcap_views``) against rosbags' reader, the
reference it replaces: the same messages in the same order, with the chunk layouts other
writers make (compressed chunks, CRCs, several messages per chunk, times out of order), a
damaged chunk refused at its place, and RecordingReader's frame sets unchanged."""
from __future__ import annotations

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer as McapWriter
from rosbags.highlevel import AnyReader

from conftest import write_bag
import mbtrack_ros.recording.bag as bag_module
from mbtrack_ros.recording.bag import BagError, RecordingReader, typestore
from mbtrack_ros.recording.mcap_views import McapViewError, McapViews

T = typestore.types
IMAGE = 'sensor_msgs/msg/Image'
INFO = 'sensor_msgs/msg/CameraInfo'


def _image(rng, w: int, h: int, stamp_ns: int):
    sec, nsec = divmod(stamp_ns, 1_000_000_000)
    header = T['std_msgs/msg/Header'](stamp=T['builtin_interfaces/msg/Time'](
        sec=sec, nanosec=nsec), frame_id='cam_optical')
    return T[IMAGE](header=header, height=h, width=w, encoding='rgb8', is_bigendian=0,
                    step=w * 3, data=rng.integers(0, 256, w * h * 3, dtype=np.uint8))


def _info(stamp_ns: int):
    sec, nsec = divmod(stamp_ns, 1_000_000_000)
    return T[INFO](header=T['std_msgs/msg/Header'](stamp=T['builtin_interfaces/msg/Time'](
        sec=sec, nanosec=nsec), frame_id='cam_optical'), height=24, width=32,
        distortion_model='plumb_bob', d=np.zeros(5), k=np.eye(3).ravel(), r=np.eye(3).ravel(),
        p=np.zeros(12), binning_x=0, binning_y=0,
        roi=T['sensor_msgs/msg/RegionOfInterest'](x_offset=0, y_offset=0, height=0, width=0,
                                                  do_rectify=False))


def _recording(path, rng, frames: int = 7):
    """A rosbag2 MCAP bag of three 32x24 cameras and camera infos; log times (and the
    order messages are written in) not sorted: cam2 is written a frame late, with a stamp
    tie between cam0 and cam1."""
    messages = []
    for k in range(frames):
        t = 10**9 + k * 66_666_667
        messages += [('/cam0/image_raw', _image(rng, 32, 24, t), t),
                     ('/cam1/image_raw', _image(rng, 32, 24, t), t),
                     ('/cam0/camera_info', _info(t), t)]
        if k:
            messages.append(('/cam2/image_raw', _image(rng, 32, 24, t - 66_666_660),
                             t - 66_666_660))
    return write_bag(path, messages)


def _rewrite(bag, compression: CompressionType, chunk_size: int):
    """The bag's MCAP file written again by the mcap library (chunks of ``chunk_size``
    bytes with ``compression`` and CRCs), messages in the same order."""
    (file,) = bag.glob('*.mcap')
    with file.open('rb') as handle:
        records = list(make_reader(handle).iter_messages(log_time_order=False))
    with file.open('wb') as handle:
        writer = McapWriter(handle, chunk_size=chunk_size, compression=compression)
        writer.start(profile='ros2')
        schemas, channels = {}, {}
        for schema, channel, message in records:
            if schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(schema.name, schema.encoding,
                                                            schema.data)
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, schemas[schema.id],
                    channel.metadata)
            writer.add_message(channels[channel.id], message.log_time, message.data,
                               message.publish_time, message.sequence)
        writer.finish()
    return file


def _rosbags(bag, topics):
    with AnyReader([bag], default_typestore=typestore) as reader:
        conns = [c for c in reader.connections if c.topic in topics]
        return [(c.topic, c.msgtype, t, bytes(raw)) for c, t, raw in reader.messages(conns)]


def _views(bag, topics):
    with McapViews(sorted(bag.glob('*.mcap'))) as views:
        return [(topic, msgtype, t, bytes(view))
                for topic, msgtype, t, view in views.messages(topics)]


@pytest.mark.parametrize('layout', ['rosbags', 'none', 'zstd', 'lz4'])
def test_mcap_views_are_the_messages_rosbags_reads(tmp_path, layout):
    """Every message, its topic, type, log time and bytes, in rosbags' order, for the
    bag as rosbags writes it (a chunk per image, no CRC) and as the mcap library writes it
    (500-byte chunks: several messages per chunk, times overlapping across chunks; no,
    zstd and lz4 compression; CRCs), for all topics and for the image topics alone; the
    frame sets RecordingReader makes from the views are those it makes from rosbags'."""
    bag = _recording(tmp_path / 'bag', np.random.default_rng(1))
    if layout != 'rosbags':
        _rewrite(bag, {'none': CompressionType.NONE, 'zstd': CompressionType.ZSTD,
                       'lz4': CompressionType.LZ4}[layout], 500)
    images = {'/cam0/image_raw', '/cam1/image_raw', '/cam2/image_raw'}
    for topics in (images | {'/cam0/camera_info'}, images):
        want = _rosbags(bag, topics)
        assert len(want) == 20 + 7 * (len(topics) - 3)
        assert _views(bag, topics) == want
    with RecordingReader(bag) as reader:
        assert reader._views is not None    # the in-place path is the one taken
        sets = list(reader.frames())
    original = bag_module._views_of
    try:
        bag_module._views_of = lambda path: None
        with RecordingReader(bag) as reader:
            assert reader._views is None
            reference = list(reader.frames())
    finally:
        bag_module._views_of = original
    assert len(sets) == len(reference) >= 7
    for got, ref in zip(sets, reference):
        assert (got.index, got.stamp_ns, got.stamps, got.missing, got.errors) == \
            (ref.index, ref.stamp_ns, ref.stamps, ref.missing, ref.errors)
        assert got.images.keys() == ref.images.keys()
        for cam, image in got.images.items():
            np.testing.assert_array_equal(image, ref.images[cam])
            assert image.flags.writeable   # a copy, not a view of the read-only mapping


def test_a_damaged_chunk_is_refused_where_it_is(tmp_path):
    """A flipped byte inside a chunk with a CRC: the views yield the messages before that
    chunk, then raise McapViewError (one line); RecordingReader raises BagError naming the
    last good frame set, as with rosbags' reader."""
    bag = _recording(tmp_path / 'bag', np.random.default_rng(2), frames=6)
    file = _rewrite(bag, CompressionType.NONE, 3000)
    with file.open('rb') as handle:
        chunks = make_reader(handle).get_summary().chunk_indexes
    damaged = sorted(chunks, key=lambda c: c.message_start_time)[len(chunks) // 2]
    data = bytearray(file.read_bytes())
    data[damaged.chunk_start_offset + damaged.chunk_length - 100] ^= 0xFF
    file.write_bytes(bytes(data))
    topics = {'/cam0/image_raw', '/cam1/image_raw', '/cam2/image_raw'}
    got = []
    with McapViews([file]) as views, pytest.raises(McapViewError) as err:
        for item in views.messages(topics):
            got.append(item[2])
    assert 'checksum' in str(err.value) and '\n' not in str(err.value)
    assert got and max(got) < damaged.message_end_time
    with RecordingReader(bag) as reader, pytest.raises(BagError) as bag_err:
        list(reader.frames())
    assert 'unreadable after frame set' in str(bag_err.value)


def test_a_file_without_a_summary_is_not_read_in_place(tmp_path):
    """A truncated MCAP file (no summary): McapViews refuses it in one line, and
    RecordingReader falls back to its stream reading of the complete records."""
    bag = _recording(tmp_path / 'bag', np.random.default_rng(3))
    (file,) = bag.glob('*.mcap')
    file.write_bytes(file.read_bytes()[:-200])
    with pytest.raises(McapViewError):
        McapViews([file])
    with RecordingReader(bag) as reader:
        assert reader._views is None and reader.damaged
