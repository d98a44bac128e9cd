"""The input path of larger cameras: image messages' CDR fields read without a copy
(``recording/cdr_images``) and the one area shrink to the working size (``Camera.fit``,
``area_shrink``), each against the reference it replaces: rosbags' deserialiser, OpenCV's
``INTER_AREA`` and a brute-force area mean."""
from __future__ import annotations

import dataclasses
import struct
from fractions import Fraction

import cv2
import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from conftest import make_room, write_bag
from mbtrack_ros.core.camera import area_shrink, block_shrink
from mbtrack_ros.recording.bag import RecordingReader, typestore
from mbtrack_ros.recording.cdr_images import COMPRESSED, IMAGE, CdrError, image_view
from mbtrack_ros.recording.images import CHANNELS, decode_raw, encode_compressed

T = typestore.types


def _header(stamp_ns: int, frame_id: str):
    sec, nsec = divmod(stamp_ns, 1_000_000_000)
    return T['std_msgs/msg/Header'](stamp=T['builtin_interfaces/msg/Time'](sec=sec,
                                                                           nanosec=nsec),
                                    frame_id=frame_id)


def _raw(rng, encoding: str, w: int, h: int, stamp_ns: int, pad: int = 0):
    step = w * CHANNELS[encoding] + pad
    return T[IMAGE](header=_header(stamp_ns, 'cam_optical'), height=h, width=w,
                    encoding=encoding, is_bigendian=0, step=step,
                    data=rng.integers(0, 256, step * h, dtype=np.uint8))


def _compressed(rng, kind: str, w: int, h: int, stamp_ns: int):
    fmt, data = encode_compressed(rng.integers(0, 256, (h, w, 3), dtype=np.uint8), kind)
    return T[COMPRESSED](header=_header(stamp_ns, 'cam_optical'), format=fmt,
                         data=np.frombuffer(data, dtype=np.uint8))


_bag = write_bag


def _rosbags_messages(path, topics):
    with AnyReader([path], default_typestore=typestore) as reader:
        conns = [c for c in reader.connections if c.topic in topics]
        return [(c.topic, c.msgtype, bytes(raw)) for c, _, raw in reader.messages(conns)]


# -- CDR fields in place ----------------------------------------------------------------------
@pytest.mark.parametrize('little', [True, False])
def test_image_view_equals_rosbags_on_every_supported_message(little):
    """Every raw encoding the decoder supports (padded rows too) and JPEG/PNG: the fields of
    ``image_view`` are those rosbags deserialises, in either byte order, and the pixels are
    a view of the caller's buffer, not a copy."""
    rng = np.random.default_rng(1)
    msgs = [_raw(rng, enc, 7, 5, 1_700_000_000_123_456_789 + i, pad=3 * (i % 2))
            for i, enc in enumerate(CHANNELS)]
    msgs += [_compressed(rng, kind, 16, 8, 42) for kind in ('jpeg', 'png')]
    for msg in msgs:
        cdr = bytearray(typestore.serialize_cdr(msg, msg.__msgtype__, little_endian=little))
        ref = typestore.deserialize_cdr(bytes(cdr), msg.__msgtype__)
        view = image_view(cdr, msg.__msgtype__)
        assert view.stamp_ns == ref.header.stamp.sec * 10**9 + ref.header.stamp.nanosec
        assert view.frame_id == ref.header.frame_id
        if msg.__msgtype__ == IMAGE:
            assert (view.encoding, view.height, view.width, view.step, view.is_bigendian) \
                == (ref.encoding, ref.height, ref.width, ref.step, ref.is_bigendian)
        else:
            assert view.format == ref.format
        assert bytes(view.data) == ref.data.tobytes()
        assert np.shares_memory(np.frombuffer(view.data, np.uint8), np.frombuffer(cdr, np.uint8))


def test_image_view_refuses_every_truncation_in_one_line():
    rng = np.random.default_rng(2)
    for msg in (_raw(rng, 'rgb8', 4, 3, 5), _compressed(rng, 'png', 4, 4, 5)):
        cdr = bytes(typestore.serialize_cdr(msg, msg.__msgtype__))
        for cut in range(len(cdr)):
            with pytest.raises(CdrError) as info:
                image_view(cdr[:cut], msg.__msgtype__)
            assert '\n' not in str(info.value)
    with pytest.raises(CdrError):
        image_view(b'\x00\x01\x00\x00' + b'\xff' * 40, IMAGE)   # a huge string length


def test_stamps_a_nanosecond_apart_do_not_stall_the_synchroniser():
    """Stamps a nanosecond apart (a broken driver, a damaged bag): a period of 1 ns still
    gives windows that move on."""
    import threading

    from mbtrack_ros.recording.sync import FrameSetSynchronizer

    sync = FrameSetSynchronizer(['a', 'b'], 0, 10**9)
    out = []

    def feed():
        for cam, stamp in (('a', 10**9), ('b', 10**9), ('a', 10**9 + 1), ('b', 10**9 + 1),
                           ('a', 10**9 + 2)):
            out.extend(sync.add(cam, stamp, cam))
        out.extend(sync.flush())

    worker = threading.Thread(target=feed, daemon=True)
    worker.start()
    worker.join(timeout=10)
    assert not worker.is_alive(), 'the synchroniser stalled'
    assert sum(len(fs.images) for fs in out) == 5 - sync.counters.dropped_frames


def test_recording_reader_reads_in_place_what_rosbags_deserialises(tmp_path):
    """RecordingReader's frame sets (pixels read in place, one resize to the working size)
    are rosbags' deserialised images through the same decoder, for a 640x480 and a
    1280x720 camera."""
    rng = np.random.default_rng(6)
    messages = []
    for k in range(6):
        t = 10**9 + k * 66_666_667
        messages.append(('/cam0/image_raw', _raw(rng, 'rgb8', 640, 480, t), t))
        messages.append(('/cam1/image_raw', _raw(rng, 'bgr8', 1280, 720, t + 5), t + 5))
    bag = _bag(tmp_path / 'bag', messages)
    room = make_room(640, 480)
    to = {'cam0': room.cameras['cam0'].at_most(76800),
          'cam1': make_room(1280, 720).cameras['cam0'].at_most(76800)}   # square pixels
    with RecordingReader(bag) as reader:
        reader.decode_to(to)
        sets = list(reader.frames())
    assert len(sets) == 6
    want = {}
    for topic, _, raw in _rosbags_messages(bag, {'/cam0/image_raw', '/cam1/image_raw'}):
        msg = typestore.deserialize_cdr(raw, IMAGE)
        cam = topic.split('/')[1]
        image = decode_raw(msg.encoding, msg.height, msg.width, msg.step, msg.data,
                           to=to[cam])
        want.setdefault(cam, []).append(image)
    for k, fs in enumerate(sets):
        assert not fs.errors
        assert fs.images['cam0'].shape == (240, 320, 3)
        assert fs.images['cam1'].shape == (208, 370, 3)
        for cam in fs.images:
            np.testing.assert_array_equal(fs.images[cam], want[cam][k])


def test_reader_gives_the_working_images_of_the_step_resize(tmp_path):
    """``mbtrack replay`` reads at the working size (``RecordingReader.decode_to``, the
    bag's pixels read in place): its frame sets are those of reading at full size (stamps,
    order, errors, missing cameras, synchroniser warnings and dropped images) with the
    images the tracker's step makes from the full-size ones (``Tracker.working_images``,
    ``Camera.fit`` after decoding), bit for bit, for a 640x480 and a 1280x720 camera."""
    from mbtrack_ros.core.tracker import Tracker, TrackerConfig

    rng = np.random.default_rng(9)
    room = make_room(640, 480)
    cams = dict(room.cameras)
    cams['cam1'] = room.cameras['cam1'].scaled(1280, 720)
    room = dataclasses.replace(room, cameras=cams)
    messages = []
    for k in range(8):
        t = 10**9 + k * 66_666_667
        messages.append(('/cam0/image_raw', _raw(rng, 'rgb8', 640, 480, t), t))
        if k != 5:   # cam1 misses a frame set, and sends one image twice (dropped)
            messages.append(('/cam1/image_raw', _raw(rng, 'bgr8', 1280, 720, t + 5), t + 5))
        if k == 3:
            messages.append(('/cam1/image_raw', _raw(rng, 'bgr8', 1280, 720, t + 5), t + 6))
    bag = _bag(tmp_path / 'bag', messages)
    tracker = Tracker(room, TrackerConfig())
    assert set(tracker.resized_cameras) == {'cam0', 'cam1'}
    with RecordingReader(bag) as reader:
        full = list(reader.frames())
        warnings, dropped = list(reader.warnings), reader.sync.counters.dropped_frames
        reader.decode_to(tracker.resized_cameras)
        here = list(reader.frames())
        assert (reader.warnings, reader.sync.counters.dropped_frames) == (warnings, dropped)
    assert dropped == 1 and any(fs.missing == ['cam1'] for fs in here)
    assert len(full) == len(here) == 8
    for old, new in zip(full, here):
        assert (new.index, new.stamp_ns, new.stamps, new.missing, new.errors) == \
            (old.index, old.stamp_ns, old.stamps, old.missing, old.errors)
        step = tracker.working_images(old.images)
        assert set(step) == set(new.images)
        for cam, image in step.items():
            work = tracker.calibration.cameras[cam]
            assert image.shape == (work.height, work.width, 3)
            np.testing.assert_array_equal(new.images[cam], image)


def test_the_live_node_converts_a_message_as_the_replay_reads_it(tmp_path):
    """tracker_node's conversion of a ``sensor_msgs/Image`` (rclpy) and the replay's reader
    of the same image in a bag give the same working image: one decoder, one resize."""
    pytest.importorskip('rclpy')
    from mbtrack_ros.nodes.conversions import image_to_rgb, rgb_to_image

    rng = np.random.default_rng(7)
    rgb = cv2.GaussianBlur(rng.integers(0, 256, (720, 1280, 3), dtype=np.uint8), (5, 5), 0)
    work = make_room(640, 480).cameras['cam0'].scaled(1280, 720).at_most(76800)
    msg = T[IMAGE](header=_header(10**9, 'cam_optical'), height=720, width=1280,
                   encoding='rgb8', is_bigendian=0, step=1280 * 3, data=rgb.reshape(-1))
    bag = _bag(tmp_path / 'bag', [('/cam0/image_raw', msg, 10**9)])
    with RecordingReader(bag) as reader:
        reader.decode_to({'cam0': work})
        (frame_set,) = list(reader.frames())
    live = image_to_rgb(rgb_to_image(rgb), expected=(1280, 720), to=work)
    np.testing.assert_array_equal(live, frame_set.images['cam0'])
    np.testing.assert_array_equal(live, work.fit(rgb))


# -- the area shrink --------------------------------------------------------------------------
def _exact_area_mean(image: np.ndarray, width: int, height: int) -> np.ndarray:
    """Brute force: each output pixel the integral of the piecewise-constant input over its
    cell divided by the cell's area, with exact rational cell borders."""
    h_in, w_in = image.shape[:2]

    def weights(n_in, n_out):
        m = np.zeros((n_out, n_in))
        s = Fraction(n_in, n_out)
        for o in range(n_out):
            a, b = o * s, (o + 1) * s
            for i in range(n_in):
                m[o, i] = float(max(Fraction(0), min(b, i + 1) - max(a, Fraction(i))) / s)
        return m

    wy, wx = weights(h_in, height), weights(w_in, width)
    return np.einsum('oi,ijc,pj->opc', wy, image.astype(np.float64), wx)


def test_area_shrink_is_the_exact_area_mean_up_to_rounding():
    rng = np.random.default_rng(8)
    for _ in range(40):
        h_in, w_in = (int(v) for v in rng.integers(1, 24, 2))
        height, width = int(rng.integers(1, h_in + 1)), int(rng.integers(1, w_in + 1))
        channels = int(rng.choice([1, 3, 4]))
        image = rng.integers(0, 256, (h_in, w_in, channels), dtype=np.uint8)
        got = area_shrink(image, width, height)
        exact = _exact_area_mean(image, width, height)
        assert got.shape == (height, width, channels)
        assert np.abs(got - exact).max() <= 0.5 + 1e-3


def _opencv_pyramid(image: np.ndarray, width: int, height: int) -> np.ndarray:
    """The pyramid of ``Camera.fit`` all in OpenCV: exact halvings, then INTER_AREA."""
    h, w = image.shape[:2]
    while h % 2 == 0 and w % 2 == 0 and h // 2 >= height and w // 2 >= width \
            and (h, w) != (height, width):
        h, w = h // 2, w // 2
        image = cv2.resize(image, (w, h), interpolation=cv2.INTER_AREA)
    return cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA)


@pytest.mark.parametrize('size', [(1280, 720), (1920, 1080), (1000, 750), (752, 480),
                                  (640, 480)])
def test_camera_fit_is_the_opencv_pyramid_within_one_grey_level(size):
    """Any input size to the working size, on noise (the hardest picture), colour, grey and
    padded rows: an integer-factor size (1280x720 of non-square pixels to 320x240: 4x3
    blocks) is the exact block mean, OpenCV's direct INTER_AREA within one grey level;
    any other within one grey level of the same pyramid done by OpenCV alone; a
    power-of-two fraction (640x480) and an area shrink alone (the numba kernel straight
    from the input) are OpenCV's direct INTER_AREA bit for bit / within one level."""
    w, h = size
    rng = np.random.default_rng(9)
    cam = make_room(8, 6).cameras['cam0'].scaled(w, h).at_most(76800)
    padded = rng.integers(0, 256, (h, w + 5, 3), dtype=np.uint8)
    image = padded[:, :w]
    got = cam.fit(image)
    assert got.shape == (cam.height, cam.width, 3)
    direct = cv2.resize(image, (cam.width, cam.height), interpolation=cv2.INTER_AREA)
    grey = image[:, :, 1].copy()
    if h % cam.height == 0 and w % cam.width == 0:
        ky, kx = h // cam.height, w // cam.width
        blocks = image.reshape(cam.height, ky, cam.width, kx, 3).astype(float).mean((1, 3))
        assert np.abs(got - blocks).max() <= 0.5 + 1e-9
        assert np.abs(got.astype(int) - direct).max() <= 1
        grey_direct = cv2.resize(grey, (cam.width, cam.height), interpolation=cv2.INTER_AREA)
        assert np.abs(cam.fit(grey).astype(int) - grey_direct).max() <= 1
    else:
        assert np.abs(got.astype(int)
                      - _opencv_pyramid(image, cam.width, cam.height)).max() <= 1
        assert np.abs(cam.fit(grey).astype(int)
                      - _opencv_pyramid(grey, cam.width, cam.height)).max() <= 1
    assert np.abs(area_shrink(image, cam.width, cam.height).astype(int) - direct).max() <= 1
    if size == (640, 480):
        np.testing.assert_array_equal(got, direct)


def test_block_shrink_is_the_exact_block_mean():
    """Against the brute-force block mean on random sizes, factors and channel counts
    (colour, grey, RGBA; a view of a larger array): the mean rounded half up, exactly."""
    rng = np.random.default_rng(12)
    for _ in range(30):
        kx, ky = (int(v) for v in rng.integers(1, 6, 2))
        w, h = (int(v) for v in rng.integers(1, 9, 2))
        channels = int(rng.choice([0, 3, 4]))
        shape = (h * ky, w * kx + 3) + ((channels,) if channels else ())
        image = rng.integers(0, 256, shape, dtype=np.uint8)[:, :w * kx]
        got = block_shrink(image, kx, ky)
        want = np.zeros((h, w) + image.shape[2:])
        for y in range(h):
            for x in range(w):
                block = image[y * ky:(y + 1) * ky, x * kx:(x + 1) * kx].astype(np.int64)
                want[y, x] = (block.sum(axis=(0, 1)) + kx * ky // 2) // (kx * ky)
        assert got.shape == want.shape and got.dtype == np.uint8
        np.testing.assert_array_equal(got, want)
    with pytest.raises(ValueError):
        block_shrink(np.zeros((6, 6, 3), np.uint8), 4, 2)
    with pytest.raises(ValueError):
        block_shrink(np.zeros((6, 6, 3), np.float32), 2, 2)


def test_area_shrink_refuses_enlarging_and_other_types():
    with pytest.raises(ValueError):
        area_shrink(np.zeros((4, 4, 3), np.uint8), 5, 4)
    with pytest.raises(ValueError):
        area_shrink(np.zeros((4, 4, 3), np.float32), 2, 2)


def test_decode_raw_of_a_view_never_aliases_it():
    """The working image outlives the message buffer it was read from."""
    rng = np.random.default_rng(10)
    buf = bytearray(rng.integers(0, 256, 64 * 48 * 3, dtype=np.uint8).tobytes())
    cam = make_room(8, 6).cameras['cam0'].scaled(64, 48)
    for to in (None, cam, cam.scaled(30, 20)):
        out = decode_raw('rgb8', 48, 64, 64 * 3, memoryview(buf), to=to)
        assert not np.shares_memory(out, np.frombuffer(buf, np.uint8))
