"""Image message conversions (rclpy messages and the shared numpy codec)."""
from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from sensor_msgs.msg import CompressedImage, Image
from std_msgs.msg import Header

from mbtrack_ros.nodes.conversions import (
    ImageConversionError, compressed_to_rgb, image_to_mono, image_to_rgb, mono_to_image,
    ns_to_stamp, rgb_to_compressed, rgb_to_image, stamp_to_ns)
from mbtrack_ros.recording.images import decode_raw


def smooth_rgb(h=48, w=64, seed=0):
    """A smooth colour image (JPEG-friendly) with random offsets."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w]
    base = rng.integers(0, 100, 3)
    img = np.stack([base[0] + 2 * xx, base[1] + 3 * yy, base[2] + xx + yy], axis=-1)
    return np.clip(img, 0, 255).astype(np.uint8)


def header(stamp_ns=1_234_567_890_123):
    h = Header()
    h.frame_id = 'cam0_optical_frame'
    h.stamp = ns_to_stamp(stamp_ns)
    return h


def test_stamp_round_trip():
    for ns in (0, 1, 999_999_999, 1_000_000_000, 1_700_000_000_123_456_789):
        assert stamp_to_ns(ns_to_stamp(ns)) == ns


@pytest.mark.parametrize('encoding', ['rgb8', 'bgr8', 'rgba8', 'bgra8'])
def test_raw_round_trip_exact(encoding):
    rgb = np.random.default_rng(1).integers(0, 256, (5, 7, 3), dtype=np.uint8)
    msg = rgb_to_image(rgb, header(), encoding=encoding)
    assert msg.encoding == encoding and msg.width == 7 and msg.height == 5
    assert msg.header.frame_id == 'cam0_optical_frame'
    out = image_to_rgb(msg)
    assert out.dtype == np.uint8 and out.shape == (5, 7, 3)
    np.testing.assert_array_equal(out, rgb)


def test_bgr8_really_swaps_channels():
    msg = Image(height=1, width=2, encoding='bgr8', step=6)
    msg.data = bytes([10, 20, 30, 40, 50, 60])
    np.testing.assert_array_equal(image_to_rgb(msg), [[[30, 20, 10], [60, 50, 40]]])


def test_mono8_round_trip_and_grey_input():
    grey = np.random.default_rng(2).integers(0, 256, (4, 6), dtype=np.uint8)
    rgb = np.repeat(grey[:, :, None], 3, axis=2)
    msg = rgb_to_image(rgb, encoding='mono8')
    assert msg.step == 6 and len(msg.data) == 24
    np.testing.assert_array_equal(image_to_rgb(msg), rgb)


def test_mono_plane_round_trip_exact_and_bad_planes_refused():
    """A packed-mask plane goes as raw mono8 and comes back bit for bit (no grey to RGB
    conversion), padded rows cropped; wrong encoding, size or length: one-line errors."""
    plane = np.random.default_rng(4).integers(0, 256, (5, 7), dtype=np.uint8)
    msg = mono_to_image(plane, header())
    assert (msg.encoding, msg.height, msg.width, msg.step) == ('mono8', 5, 7, 7)
    assert msg.header.frame_id == 'cam0_optical_frame'
    out = image_to_mono(msg, expected=(7, 5))
    assert out.dtype == np.uint8 and out.shape == (5, 7)
    np.testing.assert_array_equal(out, plane)
    out[0, 0] ^= 1                                    # a copy, not the message's buffer
    np.testing.assert_array_equal(image_to_mono(msg), plane)
    padded = Image(height=5, width=7, encoding='mono8', step=8)
    padded.data = np.pad(plane, ((0, 0), (0, 1)), constant_values=255).tobytes()
    np.testing.assert_array_equal(image_to_mono(padded), plane)
    one_line_error(lambda: image_to_mono(rgb_to_image(smooth_rgb(5, 7))), 'expected mono8')
    one_line_error(lambda: image_to_mono(msg, expected=(8, 5)), 'differs from')
    short = mono_to_image(plane)
    short.data = bytes(short.data)[:-1]
    one_line_error(lambda: image_to_mono(short), 'expected step\\*height')
    huge = Image(height=60000, width=60000, encoding='mono8', step=60000)
    one_line_error(lambda: image_to_mono(huge), 'exceeds the limit')
    one_line_error(lambda: mono_to_image(np.zeros((4, 4, 3), np.uint8)), 'expected an')


def test_padded_rows_are_cropped():
    rgb = np.random.default_rng(3).integers(0, 256, (3, 4, 3), dtype=np.uint8)
    padded = np.zeros((3, 16), np.uint8)
    padded[:, :12] = rgb.reshape(3, 12)
    padded[:, 12:] = 255
    msg = Image(height=3, width=4, encoding='rgb8', step=16)
    msg.data = padded.tobytes()
    np.testing.assert_array_equal(image_to_rgb(msg), rgb)


def test_decoded_image_does_not_alias_message():
    data = bytearray(np.arange(12, dtype=np.uint8).tobytes())
    out = decode_raw('rgb8', 2, 2, 6, data)
    data[0] = 200
    assert out[0, 0, 0] == 0
    out[0, 0, 1] = 99  # writable


def test_png_exact_and_jpeg_close():
    rgb = smooth_rgb()
    png = rgb_to_compressed(rgb, header(), 'png')
    assert 'png' in png.format and png.header.frame_id == 'cam0_optical_frame'
    np.testing.assert_array_equal(compressed_to_rgb(png), rgb)
    jpg = rgb_to_compressed(rgb, header(), 'jpeg', quality=95)
    assert 'jpeg' in jpg.format
    out = compressed_to_rgb(jpg)
    assert out.shape == rgb.shape
    err = np.abs(out.astype(int) - rgb.astype(int))
    assert err.mean() < 3.0 and err.max() < 40


def one_line_error(fn, match):
    with pytest.raises(ImageConversionError, match=match) as info:
        fn()
    assert '\n' not in str(info.value) and str(info.value)


def test_bad_inputs_raise_one_line_errors():
    good = rgb_to_image(smooth_rgb(4, 4))
    msg = Image(height=4, width=4, encoding='yuv422', step=8)
    msg.data = bytes(32)
    one_line_error(lambda: image_to_rgb(msg), 'unsupported encoding')
    short = Image(height=4, width=4, encoding='rgb8', step=12)
    short.data = bytes(good.data)[:-1]
    one_line_error(lambda: image_to_rgb(short), 'expected step\\*height')
    narrow = Image(height=4, width=4, encoding='rgb8', step=8)
    narrow.data = bytes(32)
    one_line_error(lambda: image_to_rgb(narrow), 'step 8 < width')
    empty = Image(height=0, width=4, encoding='rgb8', step=12)
    one_line_error(lambda: image_to_rgb(empty), 'empty image')
    bad_jpeg = CompressedImage(format='jpeg')
    bad_jpeg.data = b'\xff\xd8not a jpeg at all'
    one_line_error(lambda: compressed_to_rgb(bad_jpeg), 'no PNG or JPEG header')
    tiff = CompressedImage(format='tiff')
    tiff.data = b'II*\x00'
    one_line_error(lambda: compressed_to_rgb(tiff), 'unsupported compressed format')
    one_line_error(lambda: rgb_to_image(np.zeros((4, 4), np.uint8)), 'expected an')


def test_huge_declared_size_refused_before_allocating():
    huge = Image(height=60000, width=60000, encoding='rgb8', step=180000)
    huge.data = bytes(16)
    tracemalloc.start()
    try:
        one_line_error(lambda: image_to_rgb(huge), 'exceeds the limit')
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 10_000_000
    # a PNG whose header declares 20000 x 20000 pixels is refused before decoding
    png = bytearray(bytes(rgb_to_compressed(smooth_rgb(4, 4), fmt='png').data))
    png[16:24] = (20000).to_bytes(4, 'big') + (20000).to_bytes(4, 'big')
    msg = CompressedImage(format='png')
    msg.data = bytes(png)
    one_line_error(lambda: compressed_to_rgb(msg), 'exceeds the limit')
