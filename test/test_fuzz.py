"""Fuzzing the inputs a user or an attacker controls (hypothesis).

Inputs: raw and compressed image payloads (random headers and bytes, mutated PNG/JPEG
files), calibration documents (random YAML trees, mutations of a valid room calibration and
of an OpenCV-style file, random bytes), bags (byte mutations and truncations of a small bag
written in a temporary directory) and CSV files (tracks, ground truth). The property is the
same everywhere: every input ends in the documented error type (``ImageConversionError``,
``CalibrationError``, ``BagError``, ``CsvFormatError``) or in a valid result, within a time
bound and (for images, where the size comes from the attacker) a memory bound.

Runs are derandomised (the same examples every run), so CI is reproducible; the default
profile keeps the whole module under ~60 s. A longer run: set ``MBTRACK_FUZZ_EXAMPLES`` to
the number of examples per test (e.g. ``MBTRACK_FUZZ_EXAMPLES=5000 pytest test/test_fuzz.py``;
the default is 200 per test, a fifth of that for the bag tests).
"""
from __future__ import annotations

import math
import os
import time
import tracemalloc

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from conftest import make_room
from mbtrack_ros.core.camera import CalibrationError, RoomCalibration
from mbtrack_ros.recording.calibration_io import load_calibration, read_calibration
from mbtrack_ros.recording.csvfiles import CsvFormatError, read_ground_truth, read_tracks
from mbtrack_ros.recording.images import (
    MAX_SIDE, ImageConversionError, decode_compressed, decode_raw, encode_compressed)

EXAMPLES = int(os.environ.get('MBTRACK_FUZZ_EXAMPLES', '200'))
SECONDS = 2.0  # the longest any single input may take (a shared 2-core machine)
MEGABYTES = 64  # the most Python/numpy memory one image may allocate

FUZZ = settings(max_examples=EXAMPLES, derandomize=True, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                       HealthCheck.function_scoped_fixture])
FUZZ_BAGS = settings(FUZZ, max_examples=max(5, EXAMPLES // 5))


class _Bounded:
    """Time (and with ``memory``, tracemalloc peak) of the code in the ``with`` block."""

    def __init__(self, memory: bool = False) -> None:
        self.memory = memory

    def __enter__(self):
        if self.memory:
            tracemalloc.start()
        self.t0 = time.perf_counter()
        return self

    def __exit__(self, *exc):
        spent = time.perf_counter() - self.t0
        peak = 0
        if self.memory:
            _, peak = tracemalloc.get_traced_memory()
            tracemalloc.stop()
        assert spent < SECONDS, f'took {spent:.2f} s'
        assert peak < MEGABYTES * 2 ** 20, f'allocated {peak / 2 ** 20:.0f} MB'
        return False


# -- images ----------------------------------------------------------------------------------

ENCODINGS = st.one_of(st.sampled_from(['rgb8', 'bgr8', 'mono8', 'rgba8', 'bgra8', 'RGB8',
                                       'yuv422', '16UC1', '']), st.text(max_size=12))
SIDES = st.one_of(st.integers(-3, 70), st.sampled_from([0, 1, MAX_SIDE, MAX_SIDE + 1,
                                                        60000, 2 ** 31 - 1]))
EXPECTED = st.one_of(st.none(), st.tuples(st.integers(1, 64), st.integers(1, 64)))


@FUZZ
@given(encoding=ENCODINGS, height=SIDES, width=SIDES, step=st.integers(-5, 300),
       data=st.binary(max_size=4096), expected=EXPECTED,
       max_scale=st.sampled_from([1.0, 4.0]))
def test_raw_images(encoding, height, width, step, data, expected, max_scale):
    with _Bounded(memory=True):
        try:
            rgb = decode_raw(encoding, height, width, step, data, expected=expected,
                             max_scale=max_scale)
        except ImageConversionError as err:
            assert str(err) and '\n' not in str(err) and err.cause
            return
    assert rgb.dtype == np.uint8 and rgb.shape == (height, width, 3)
    if expected is not None and max_scale == 1.0:
        assert (width, height) == expected


def _encoded() -> list[bytes]:
    rng = np.random.default_rng(7)
    image = rng.integers(0, 256, (24, 32, 3), dtype=np.uint8)
    return [encode_compressed(image, kind)[1] for kind in ('png', 'jpeg')]


_SEEDS = _encoded()


@st.composite
def compressed_payloads(draw) -> bytes:
    kind = draw(st.sampled_from(['mutated', 'random', 'header']))
    if kind == 'random':
        return draw(st.binary(max_size=2048))
    data = bytearray(draw(st.sampled_from(_SEEDS)))
    if kind == 'header':  # a real file with another declared size
        w, h = draw(SIDES), draw(SIDES)
        if data[:4] == b'\x89PNG':
            data[16:24] = (w % 2 ** 32).to_bytes(4, 'big') + (h % 2 ** 32).to_bytes(4, 'big')
        else:
            i = data.find(b'\xff\xc0')
            data[i + 5:i + 9] = (h % 2 ** 16).to_bytes(2, 'big') + (w % 2 ** 16).to_bytes(
                2, 'big')
    for _ in range(draw(st.integers(0, 8))):
        at = draw(st.integers(0, len(data) - 1))
        data[at] = draw(st.integers(0, 255))
    cut = draw(st.integers(1, len(data)))
    return bytes(data[:cut])


@FUZZ
@given(fmt=st.one_of(st.sampled_from(['png', 'jpeg', 'rgb8; jpeg compressed bgr8', 'tiff']),
                     st.text(max_size=10)),
       data=compressed_payloads(), expected=EXPECTED, max_scale=st.sampled_from([1.0, 4.0]))
def test_compressed_images(fmt, data, expected, max_scale):
    with _Bounded(memory=True):
        try:
            rgb = decode_compressed(fmt, data, expected=expected, max_scale=max_scale)
        except ImageConversionError as err:
            assert str(err) and '\n' not in str(err) and err.cause
            return
    assert rgb.dtype == np.uint8 and rgb.ndim == 3 and rgb.shape[2] == 3
    if expected is not None:
        h, w = rgb.shape[:2]
        assert w <= max_scale * expected[0] and h <= max_scale * expected[1]


# -- calibration documents -------------------------------------------------------------------

LEAVES = st.one_of(
    st.none(), st.booleans(), st.integers(-10 ** 30, 10 ** 30),
    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=8),
    st.sampled_from([0, 1, -1, 1e6, 1e300, 8192, 8193, 0.5]))
TREES = st.recursive(LEAVES, lambda inner: st.one_of(
    st.lists(inner, max_size=6), st.dictionaries(st.text(max_size=6), inner, max_size=5)),
    max_leaves=20)


def _paths(node, prefix=()):
    """Every (path, value) of a YAML tree."""
    yield prefix, node
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _paths(v, prefix + (i,))


@st.composite
def calibration_documents(draw):
    kind = draw(st.sampled_from(['mutated', 'mutated', 'tree']))
    if kind == 'tree':
        return draw(TREES)
    doc = make_room().to_dict()
    for _ in range(draw(st.integers(1, 3))):
        paths = [p for p, _ in _paths(doc) if p]
        path = draw(st.sampled_from(paths))
        parent = doc
        for key in path[:-1]:
            parent = parent[key]
        if draw(st.booleans()) and isinstance(parent, dict):
            del parent[path[-1]]
        else:
            parent[path[-1]] = draw(TREES)
    return doc


def _dump(doc) -> str:
    try:
        return yaml.safe_dump(doc, sort_keys=False, allow_unicode=True)
    except (yaml.YAMLError, ValueError):
        return '[unrepresentable'


@pytest.fixture(scope='module')
def scratch(tmp_path_factory):
    return tmp_path_factory.mktemp('fuzz')


def _calibration_ok(result: RoomCalibration) -> None:
    assert result.cameras
    x0, y0, x1, y1 = result.floor
    assert all(math.isfinite(v) for v in result.floor) and x1 > x0 and y1 > y0
    for cam in result.cameras.values():
        assert np.all(np.isfinite(cam.K)) and np.all(np.isfinite(cam.dist))
        assert 1 <= cam.width <= MAX_SIDE and 1 <= cam.height <= MAX_SIDE


@FUZZ
@given(doc=calibration_documents(), raw=st.one_of(st.none(), st.binary(max_size=300)))
def test_room_calibration_documents(scratch, doc, raw):
    path = scratch / 'room.yaml'
    path.write_bytes(raw if raw is not None else _dump(doc).encode('utf-8'))
    with _Bounded():
        try:
            result = load_calibration(path, 'room', warn=lambda line: None)
        except CalibrationError as err:
            assert str(err) and '\n' not in str(err)
            return
    _calibration_ok(result)


@FUZZ
@given(doc=TREES, entry=st.dictionaries(
    st.sampled_from(['K', 'dist', 'R', 't', 'image_size', 'width', 'height', 'rvec']),
    TREES, max_size=7))
def test_opencv_calibration_documents(scratch, doc, entry):
    import json
    path = scratch / 'calib.json'
    try:
        text = json.dumps({'cam0': entry, 'cam1': doc}, allow_nan=True)
    except (TypeError, ValueError):
        return
    path.write_text(text)
    with _Bounded():
        try:
            result = read_calibration(path, 'opencv')
        except CalibrationError as err:
            assert str(err) and '\n' not in str(err)
            return
    _calibration_ok(result)


# -- bags --------------------------------------------------------------------------------------

@pytest.fixture(scope='module')
def small_bag(tmp_path_factory):
    """A 6-frame recording of 2 cameras (32x24 rgb8) with camera infos and ground truth."""
    from mbtrack_ros.recording.bag import RecordingWriter
    from mbtrack_ros.recording.csvfiles import GroundTruthRow

    room = make_room(width=32, height=24)
    path = tmp_path_factory.mktemp('bag') / 'bag'
    rng = np.random.default_rng(3)
    with RecordingWriter(path, room) as writer:
        for k in range(6):
            stamp = 10 ** 9 + k * 66_666_667
            writer.write_frame(stamp, {c: rng.integers(0, 256, (24, 32, 3), dtype=np.uint8)
                                       for c in room.names})
            writer.write_ground_truth(stamp, [GroundTruthRow(stamp, k, 1, 2.0, 2.0, 1.7,
                                                             False, ())])
    return path


@FUZZ_BAGS
@given(data=st.data())
def test_mutated_bags(small_bag, scratch, data):
    import shutil

    from mbtrack_ros.recording.bag import BagError, RecordingReader
    mcap = next(small_bag.glob('*.mcap'))
    original = mcap.read_bytes()
    target = scratch / 'bag'
    if not target.exists():
        shutil.copytree(small_bag, target)
    blob = bytearray(original)
    mode = data.draw(st.sampled_from(['flip', 'block', 'truncate']))
    if mode == 'flip':
        for _ in range(data.draw(st.integers(1, 30))):
            blob[data.draw(st.integers(0, len(blob) - 1))] = data.draw(st.integers(0, 255))
    elif mode == 'block':
        at = data.draw(st.integers(0, len(blob) - 1))
        blob[at:at + 200] = data.draw(st.binary(min_size=200, max_size=200))
    else:
        blob = blob[: data.draw(st.integers(0, len(blob)))]
    (target / mcap.name).write_bytes(bytes(blob))
    with _Bounded():
        try:
            with RecordingReader(target) as reader:
                sets = list(reader.frames())
                reader.camera_infos()
                truth = reader.ground_truth()
        except BagError as err:
            assert str(err)
            return
    for fs in sets:
        for image in fs.images.values():
            assert image.dtype == np.uint8 and image.ndim == 3
    assert all(math.isfinite(r.x) or math.isnan(r.x) for r in truth)


# -- CSV files ---------------------------------------------------------------------------------

CELLS = st.one_of(st.integers(-2 ** 70, 2 ** 70).map(str), st.floats().map(str),
                  st.text(max_size=6), st.sampled_from(['', 'nan', 'inf', '1e400', '0x10']))


@FUZZ
@given(rows=st.lists(st.lists(CELLS, min_size=0, max_size=9), max_size=6),
       which=st.sampled_from(['tracks', 'truth']), raw=st.one_of(
           st.none(), st.binary(max_size=200)))
def test_csv_files(scratch, rows, which, raw):
    import csv
    import io
    header = ('stamp_ns,frame,track_id,x,y,visibility,existence' if which == 'tracks'
              else 'stamp_ns,frame,person_id,x,y,z_head,sitting,visible_cameras')
    buffer = io.StringIO()
    csv.writer(buffer).writerows(rows)
    path = scratch / 'file.csv'
    path.write_bytes(raw if raw is not None
                     else (header + '\n' + buffer.getvalue()).encode('utf-8', 'replace'))
    reader = read_tracks if which == 'tracks' else read_ground_truth
    with _Bounded():
        try:
            result = reader(path)
        except CsvFormatError as err:
            assert str(err) and '\n' not in str(err)
            return
    for row in result:
        assert -2 ** 63 <= row.stamp_ns < 2 ** 63 and -2 ** 63 <= row.frame < 2 ** 63


# -- the node's image callback ----------------------------------------------------------------

@pytest.fixture(scope='module')
def fuzz_node(tmp_path_factory):
    os.environ.setdefault('ROS_DOMAIN_ID', str(100 + os.getpid() % 100))
    import rclpy
    from rclpy.context import Context

    from mbtrack_ros.nodes.tracker_node import TrackerNode
    path = tmp_path_factory.mktemp('node') / 'room.yaml'
    make_room(width=32, height=24).save(path)
    ctx = Context()
    rclpy.init(context=ctx)
    node = TrackerNode(cli_args=['--ros-args', '-p', f'calibration_file:={path}',
                                 '-p', 'warm_up:=false', '-p', 'detection.enabled:=false',
                                 '-p', 'rescale_images:=true'],
                       context=ctx, step_thread=False)
    node.get_logger().set_level(40)  # errors only: the fuzzing makes every warning
    yield node
    node.destroy_node()
    rclpy.try_shutdown(context=ctx)


@FUZZ
@given(compressed=st.booleans(), encoding=ENCODINGS, height=SIDES, width=SIDES,
       step=st.integers(-5, 300), data=st.binary(max_size=4096), payload=compressed_payloads(),
       fmt=st.sampled_from(['png', 'jpeg', 'bmp']),
       frame_id=st.sampled_from(['', 'cam0_optical_frame', 'cam1_optical_frame', 'x' * 300]),
       sec=st.integers(0, 2 ** 31 - 1), nanosec=st.integers(0, 999_999_999))
def test_node_image_callback(fuzz_node, compressed, encoding, height, width, step, data,
                             payload, fmt, frame_id, sec, nanosec):
    """Any image message ends refused and counted, or in the synchroniser at the calibrated
    size; the callback never raises and stays within the time and memory bounds."""
    from sensor_msgs.msg import CompressedImage, Image
    node = fuzz_node
    if compressed:
        msg = CompressedImage(format=fmt)
        msg.data = payload
    else:
        msg = Image(encoding=encoding, height=height % 2 ** 32, width=width % 2 ** 32,
                    step=step % 2 ** 32)
        msg.data = data
    msg.header.frame_id = frame_id
    msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
    dropped, received = node._dropped, node._received
    node.sync.reset()
    with node._lock:
        node._pending.clear()
    with _Bounded(memory=True):
        node._on_image('cam0', msg)
    assert node._received == received + 1
    if node._dropped == dropped:  # accepted: in the synchroniser, at the calibrated size
        assert node.sync.pending['cam0'] == 1
        image = next(fs for fs in node.sync.flush() if 'cam0' in fs.images).images['cam0']
        assert image.shape == (24, 32, 3) and image.dtype == np.uint8
    else:
        assert node._dropped == dropped + 1 and node.sync.pending['cam0'] == 0
