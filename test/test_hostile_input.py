"""Hostile input (issue 55, rows D1-D17): each defect a user or an attacker could trigger,
with the behaviour promised instead: one line and exit code 2 in a command, a throttled
warning and a count in the node, bounded work and memory per message."""
from __future__ import annotations

import os

import numpy as np
import pytest
import yaml

from conftest import make_room
from mbtrack_ros.cli import main
from mbtrack_ros.core.camera import CalibrationError, Camera, RoomCalibration, look_at


def load_calibration(*args, **kwargs):
    from mbtrack_ros.recording.calibration_io import load_calibration as load
    return load(*args, **kwargs)


def _one_error_line(capsys, prog: str = 'mbtrack replay') -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith(f'{prog}: error: '), err
    assert 'Traceback' not in err[0]
    return err[0]


@pytest.fixture
def calib_doc() -> dict:
    return make_room().to_dict()


def _write(tmp_path, doc, name='room.yaml'):
    path = tmp_path / name
    path.write_text(yaml.safe_dump(doc, sort_keys=False) if not isinstance(doc, str) else doc)
    return path


def _replay_with(tmp_path, config, *extra):
    bag = tmp_path / 'bag'
    bag.mkdir(exist_ok=True)
    return main(['replay', str(bag), '--config', str(config), '--out', str(tmp_path / 'o'),
                 *extra])


# -- D1: files that are not UTF-8 -------------------------------------------------------------

def test_d1_binary_calibration_and_params_are_one_line_errors(tmp_path, capsys, calib_doc):
    junk = tmp_path / 'junk.yaml'
    junk.write_bytes(bytes(range(128, 256)) * 4)
    assert _replay_with(tmp_path, junk) == 2
    line = _one_error_line(capsys)
    assert str(junk) in line and 'UTF-8' in line
    good = _write(tmp_path, calib_doc)
    assert _replay_with(tmp_path, good, '--params', str(junk)) == 2
    line = _one_error_line(capsys)
    assert str(junk) in line and 'UTF-8' in line
    with pytest.raises(CalibrationError, match='UTF-8'):
        load_calibration(junk, 'room')


# -- D2: wrong types and absurd ranges ----------------------------------------------------------

def _mutate(doc: dict, where: str, value) -> dict:
    cam = doc['cameras'][0]
    if where == 'image_width':
        cam['image_width'] = value
    elif where == 'distortion_coefficients':
        cam['distortion_coefficients']['data'] = value
    elif where == 'entry_zones':
        doc['entry_zones'] = value
    elif where == 'x_max':
        doc['floor']['x_max'] = value
    elif where == 'camera_matrix':
        cam['camera_matrix']['data'] = value
    elif where == 'translation':
        cam['extrinsics']['translation'] = value
    return doc


@pytest.mark.parametrize('where, value, needle', [
    ('image_width', 'abc', 'camera cam0: image_width'),
    ('image_width', 1e9, 'camera cam0: image_width'),
    pytest.param('image_width', 10 ** 400, 'camera cam0: image_width', id='image_width-huge'),
    ('distortion_coefficients', ['a', 'b', 0, 0, 0], 'camera cam0: distortion_coefficients'),
    ('distortion_coefficients', 'text', 'camera cam0: distortion_coefficients'),
    ('entry_zones', [['a', 0, 1, 1]], 'entry_zones[0]'),
    ('entry_zones', [[0.0, 1.0]], 'entry_zones[0]'),
    ('entry_zones', 'everywhere', 'entry_zones'),
    ('x_max', float('inf'), 'floor'),
    ('x_max', 1e6, 'floor'),
    ('x_max', 'far', 'floor: x_max'),
    ('camera_matrix', [1, 2, 3], 'camera cam0: K'),
    ('translation', [[1, 2], [3]], 'camera cam0: t'),
])
def test_d2_wrong_types_and_ranges_are_one_line_errors(tmp_path, capsys, calib_doc, where,
                                                        value, needle):
    path = _write(tmp_path, _mutate(calib_doc, where, value))
    assert _replay_with(tmp_path, path) == 2
    line = _one_error_line(capsys)
    assert str(path) in line and needle in line


def test_d2_floor_side_is_capped():
    from mbtrack_ros.core.camera import MAX_FLOOR_SIDE
    room = make_room()
    with pytest.raises(CalibrationError, match='largest floor side'):
        RoomCalibration(room.cameras, (0.0, 0.0, MAX_FLOOR_SIDE + 1.0, 5.0))


# -- D3: non-finite distortion --------------------------------------------------------------------

@pytest.mark.parametrize('bad', [float('nan'), float('inf')])
def test_d3_non_finite_distortion_refused(tmp_path, capsys, calib_doc, bad):
    calib_doc['cameras'][1]['distortion_coefficients']['data'][0] = bad
    path = _write(tmp_path, calib_doc)
    assert _replay_with(tmp_path, path) == 2
    line = _one_error_line(capsys)
    assert 'camera cam1: distortion_coefficients' in line and 'non-finite' in line
    room = make_room()
    cam = room.cameras['cam0']
    with pytest.raises(CalibrationError, match='non-finite'):
        Camera('x', 160, 120, cam.K, [bad, 0, 0, 0, 0], cam.R, cam.t)


# -- D14: YAML syntax errors ------------------------------------------------------------------

def test_d14_yaml_syntax_error_is_one_line(tmp_path, capsys):
    path = _write(tmp_path, 'cameras: [\n  - camera_name: cam0\n    bad: : :\nfloor: {')
    assert _replay_with(tmp_path, path) == 2
    line = _one_error_line(capsys)
    assert 'not valid YAML' in line and 'line' in line


# -- D17: cameras that cannot see the floor -----------------------------------------------------

def _looking_up(room: RoomCalibration, names) -> RoomCalibration:
    cams = dict(room.cameras)
    for name in names:
        cam = cams[name]
        R, t = look_at(cam.center, cam.center + np.array([0.01, 0.0, 5.0]))
        cams[name] = Camera(name, cam.width, cam.height, cam.K, cam.dist, R, t)
    return RoomCalibration(cams, room.floor, entry_zones=room.entry_zones)


def test_d17_camera_blind_to_the_floor_warns_and_all_blind_refused(tmp_path, capsys):
    room = make_room()
    views = room.floor_views()
    assert all(v > 0.2 for v in views.values())
    one = tmp_path / 'one.yaml'
    _looking_up(room, ['cam1']).save(one)
    warnings = []
    load_calibration(one, 'room', warn=warnings.append)
    assert len(warnings) == 1 and 'camera cam1' in warnings[0] and str(one) in warnings[0]
    both = tmp_path / 'both.yaml'
    _looking_up(room, ['cam0', 'cam1']).save(both)
    assert _replay_with(tmp_path, both) == 2
    line = _one_error_line(capsys)
    assert 'no camera sees the floor' in line and str(both) in line
    # the node refuses it too (one line through ParamsError)
    os.environ.setdefault('ROS_DOMAIN_ID', str(100 + os.getpid() % 100))
    from mbtrack_ros.nodes.params import ParamsError
    from mbtrack_ros.nodes.tracker_node import TrackerNode
    import rclpy
    from rclpy.context import Context
    ctx = Context()
    rclpy.init(context=ctx)
    try:
        for path, needle in ((both, 'no camera sees the floor'),):
            with pytest.raises(ParamsError, match=needle):
                TrackerNode(cli_args=['--ros-args', '-p', f'calibration_file:={path}',
                                      '-p', 'warm_up:=false'], context=ctx)
        junk = tmp_path / 'junk.yaml'
        junk.write_bytes(bytes(range(128, 256)))
        with pytest.raises(ParamsError, match='UTF-8'):  # D1 in the node
            TrackerNode(cli_args=['--ros-args', '-p', f'calibration_file:={junk}',
                                  '-p', 'warm_up:=false'], context=ctx)
    finally:
        rclpy.try_shutdown(context=ctx)


# -- D10: particle caps ---------------------------------------------------------------------------

@pytest.mark.parametrize('option, value, needle', [
    ('--particles', '10000000', 'particles must be at most 100000'),
    ('--joint-particles', '100000000', 'joint_particles must be at most 1000000'),
])
def test_d10_particles_capped_in_replay(tmp_path, capsys, calib_doc, option, value, needle):
    path = _write(tmp_path, calib_doc)
    assert _replay_with(tmp_path, path, option, value) == 2
    assert needle in _one_error_line(capsys)


# -- D11: CSV integers beyond 64 bits ----------------------------------------------------------

_HUGE = str(2 ** 64 + 5)


def _truth_csv(path, stamp='1000', pid='1'):
    path.write_text('stamp_ns,frame,person_id,x,y,z_head,sitting,visible_cameras\n'
                    f'{stamp},0,{pid},1.0,1.0,1.7,0,cam0\n')
    return path


def _tracks_csv(path, stamp='1000', tid='1'):
    path.write_text(f'stamp_ns,frame,track_id,x,y\n{stamp},0,{tid},1.0,1.0\n')
    return path


@pytest.mark.parametrize('which', ['stamp', 'id'])
def test_d11_huge_csv_integers_are_one_line_errors(tmp_path, capsys, calib_doc, which):
    from mbtrack_ros.recording.csvfiles import CsvFormatError, read_ground_truth
    stamp = _HUGE if which == 'stamp' else '1000'
    ident = _HUGE if which == 'id' else '1'
    bad_truth = _truth_csv(tmp_path / 'bad_gt.csv', stamp, ident)
    bad_tracks = _tracks_csv(tmp_path / 'bad_tracks.csv', stamp, ident)
    truth = _truth_csv(tmp_path / 'gt.csv')
    tracks = _tracks_csv(tmp_path / 'tracks.csv')
    with pytest.raises(CsvFormatError, match='64-bit'):  # the node's init_ground_truth
        read_ground_truth(bad_truth)
    assert main(['eval', str(bad_tracks), str(truth), '--no-plots']) == 2
    assert '64-bit' in _one_error_line(capsys, 'mbtrack eval')
    assert main(['eval', str(tracks), str(bad_truth), '--no-plots']) == 2
    assert '64-bit' in _one_error_line(capsys, 'mbtrack eval')
    path = _write(tmp_path, calib_doc)
    assert _replay_with(tmp_path, path, '--eval', str(bad_truth)) == 2
    assert '64-bit' in _one_error_line(capsys)


# -- D13: an output path that is a directory ----------------------------------------------

def test_d13_tracks_csv_directory_is_one_line_error(tmp_path, capsys, calib_doc):
    path = _write(tmp_path, calib_doc)
    (tmp_path / 'o' / 'tracks.csv').mkdir(parents=True)
    assert _replay_with(tmp_path, path) == 2
    assert 'tracks.csv exists and is not a file' in _one_error_line(capsys)


# -- D4, D12, D15 and undecodable images: replay integrity -------------------------------------

@pytest.fixture(scope='module')
def recording(tmp_path_factory):
    out = tmp_path_factory.mktemp('rec') / 'seq'
    assert main(['synth', 'lanz-seq1-short', str(out), '--frames', '24', '--width', '160',
                 '--height', '120']) == 0
    return out


def _rewrite(recording, dst, plan):
    """A copy of ``recording`` whose bag holds the frames ``plan(frame sets)`` returns:
    (stamp, {camera: rgb or a bad-encoding marker}) pairs, written in that order."""
    import shutil

    from mbtrack_ros.recording.bag import (
        IMAGE, RecordingReader, RecordingWriter, _header, _T, typestore)
    shutil.copytree(recording, dst, ignore=shutil.ignore_patterns('bag'))
    calib = RoomCalibration.load(recording / 'calibration.yaml')
    with RecordingReader(recording) as reader:
        sets = [(fs.stamp_ns, dict(fs.images)) for fs in reader.frames()]
    with RecordingWriter(dst / 'bag', calib) as writer:
        for stamp, images in plan(sets):
            good = {c: im for c, im in images.items() if im is not None}
            if good:
                writer.write_frame(stamp, good)
            for cam in [c for c, im in images.items() if im is None]:
                c = calib.cameras[cam]
                msg = _T[IMAGE](header=_header(stamp, c.frame_id), height=c.height,
                                width=c.width, encoding='yuv422', is_bigendian=0,
                                step=c.width * 2,
                                data=np.zeros(c.width * c.height * 2, np.uint8))
                writer._writer.write(writer._image_conn[cam], stamp,
                                     typestore.serialize_cdr(msg, IMAGE))
    return dst


def _replay(rec, out, *extra):
    gt = rec / 'ground_truth.csv'
    return main(['replay', str(rec), '--out', str(out), '--init-from', str(gt),
                 '--particles', '20', *extra])


def test_d4_repeated_stamps_never_processed_twice(recording, tmp_path, capsys):
    from mbtrack_ros.recording.csvfiles import read_tracks

    def doubled(sets):
        out = []
        for stamp, images in sets:
            out += [(stamp, images), (stamp, images)]  # every image message twice
        out += [(sets[3][0], sets[3][1])]  # a jump back onto an earlier stamp
        return out

    rec = _rewrite(recording, tmp_path / 'rec', doubled)
    gt = rec / 'ground_truth.csv'
    assert _replay(rec, tmp_path / 'out', '--eval', str(gt)) == 0
    captured = capsys.readouterr()
    rows = read_tracks(tmp_path / 'out' / 'tracks.csv')
    keys = [(r.stamp_ns, r.track_id) for r in rows]
    assert len(keys) == len(set(keys))  # no duplicate (stamp, track) rows
    assert len({r.stamp_ns for r in rows}) == 24
    assert 'MOTA' in captured.out
    # the synchroniser places each stamp once: the 24 repeated images and the jump back are
    # dropped and counted
    assert 'dropped 25 image(s) that fit no frame set' in captured.err
    assert ' 24 frames,' in captured.err


def test_undecodable_images_counted_in_summary_and_tracks_mcap(recording, tmp_path, capsys):
    def broken(sets):
        return [(s, {c: (None if k in (2, 5, 9) else im) for c, im in images.items()})
                for k, (s, images) in enumerate(sets)]

    rec = _rewrite(recording, tmp_path / 'rec', broken)
    assert _replay(rec, tmp_path / 'out') == 0
    err = capsys.readouterr().err
    assert 'dropped 3 undecodable image(s)' in err and 'yuv422' in err
    from rosbags.highlevel import AnyReader

    from mbtrack_ros.recording.bag import typestore
    with AnyReader([tmp_path / 'out' / 'tracks.mcap'], default_typestore=typestore) as bag:
        conns = [c for c in bag.connections if c.topic == '/diagnostics']
        last = None
        for conn, _, raw in bag.messages(connections=conns):
            last = bag.deserialize(raw, conn.msgtype)
    values = {kv.key: kv.value for kv in last.status[0].values}
    assert values['dropped images (bad)'] == '3'


def _damage_chunk(rec, dst, rel=44, fill=b'\0'):
    """``rec`` copied to ``dst`` with 200 bytes of its last MCAP chunk's header
    overwritten (a zeroed CRC and record length: the reader skips the chunk)."""
    import shutil

    from mcap.reader import make_reader
    shutil.copytree(rec, dst)
    mcap = next((dst / 'bag').glob('*.mcap'))
    data = bytearray(mcap.read_bytes())
    with mcap.open('rb') as handle:
        chunks = make_reader(handle).get_summary().chunk_indexes
    start = chunks[-1].chunk_start_offset + rel
    data[start:start + 200] = fill * 200
    mcap.write_bytes(bytes(data))
    return dst


def test_d12_damaged_chunk_reported_with_the_lost_frame_sets(recording, tmp_path, capsys):
    from mcap.reader import make_reader

    mcap = next((recording / 'bag').glob('*.mcap'))
    with mcap.open('rb') as handle:
        if len(make_reader(handle).get_summary().chunk_indexes) < 2:
            pytest.fail('the test recording needs two chunks')
    rec = _damage_chunk(recording, tmp_path / 'rec')
    assert _replay(rec, tmp_path / 'out') == 1
    err = capsys.readouterr().err.strip().splitlines()
    line = [e for e in err if 'error' in e]
    assert len(line) == 1 and 'damaged bag' in line[0] and 'unreadable' in line[0]
    assert 'frame set' in line[0] and 'Traceback' not in '\n'.join(err)


def test_d15_mutated_bags_raise_bag_error_only(recording, tmp_path):
    """camera_infos() and ground_truth() on byte-mutated bags: a result or BagError."""
    import shutil

    from mbtrack_ros.recording.bag import BagError, RecordingReader
    mcap = next((recording / 'bag').glob('*.mcap'))
    original = mcap.read_bytes()
    rng = np.random.default_rng(55)
    dst = tmp_path / 'rec'
    shutil.copytree(recording, dst)
    target = next((dst / 'bag').glob('*.mcap'))
    outcomes = set()
    for _ in range(30):
        data = bytearray(original)
        for at in rng.integers(0, len(data), size=rng.integers(1, 40)):
            data[at] = int(rng.integers(0, 256))
        target.write_bytes(bytes(data))
        try:
            with RecordingReader(dst) as reader:
                reader.camera_infos()
                reader.ground_truth()
            outcomes.add('ok')
        except BagError:
            outcomes.add('error')
    assert outcomes <= {'ok', 'error'}
    # messages whose CDR is garbage (rosbags raises SerdeError deserialising them)
    from mbtrack_ros.recording.bag import (
        GROUND_TRUTH_TOPIC, POINT_CLOUD, RecordingWriter)
    calib = RoomCalibration.load(recording / 'calibration.yaml')
    garbage = b'\x00\x01\x00\x00' + bytes([0xff] * 12)
    with RecordingWriter(tmp_path / 'garbage', calib) as writer:
        cam = calib.names[0]
        writer._writer.write(writer._info_conn[cam], 1, garbage)
        conn = writer._writer.add_connection(GROUND_TRUTH_TOPIC, POINT_CLOUD,
                                             typestore=writer_typestore())
        writer._writer.write(conn, 1, garbage)
    with RecordingReader(tmp_path / 'garbage') as reader:
        with pytest.raises(BagError, match='cannot deserialise'):
            reader.camera_infos()
        with pytest.raises(BagError, match='cannot deserialise'):
            reader.ground_truth()


def writer_typestore():
    from mbtrack_ros.recording.bag import typestore
    return typestore


def test_bag_player_plays_a_truncated_bag_up_to_the_damage(recording, tmp_path, capsys):
    import re
    import shutil

    from mbtrack_ros.nodes import bag_player
    damaged = tmp_path / 'rec'
    shutil.copytree(recording, damaged)
    mcap = next((damaged / 'bag').glob('*.mcap'))
    data = mcap.read_bytes()
    mcap.write_bytes(data[: int(len(data) * 0.75)])  # cut the file: last chunk damaged
    code = bag_player.main(['bag_player', '--ros-args', '-p', f'bag:={damaged}',
                            '-p', 'rate:=100.0', '-p', 'start_delay:=0.0'])
    err = capsys.readouterr().err
    assert code == 1, err
    played = re.search(r'bag_player: error: .* is damaged; played (\d+) messages', err)
    assert played and 0 < int(played.group(1)) < 72, err


# -- the node: D4, D5, D6, D7, D8, D16 ----------------------------------------------------------

@pytest.fixture
def node_context():
    os.environ.setdefault('ROS_DOMAIN_ID', str(100 + os.getpid() % 100))
    import rclpy
    from rclpy.context import Context
    ctx = Context()
    rclpy.init(context=ctx)
    yield ctx
    rclpy.try_shutdown(context=ctx)


def _node(ctx, tmp_path, *params, step_thread=False):
    from mbtrack_ros.nodes.tracker_node import TrackerNode
    path = tmp_path / 'room.yaml'
    make_room().save(path)
    args = ['--ros-args', '-p', f'calibration_file:={path}', '-p', 'warm_up:=false',
            '-p', 'detection.enabled:=false']
    for p in params:
        args += ['-p', p]
    return TrackerNode(cli_args=args, context=ctx, step_thread=step_thread)


def _raw(rgb, stamp, frame_id='cam0_optical_frame'):
    from mbtrack_ros.nodes.conversions import rgb_to_image
    from mbtrack_ros.nodes.messages import make_header
    return rgb_to_image(rgb, make_header(stamp, frame_id))


def _compressed(data: bytes, stamp, fmt='png', frame_id='cam0_optical_frame'):
    from sensor_msgs.msg import CompressedImage

    from mbtrack_ros.nodes.messages import make_header
    msg = CompressedImage(format=fmt)
    msg.header = make_header(stamp, frame_id)
    msg.data = data
    return msg


def _png_header(width: int, height: int) -> bytes:
    """A PNG signature and IHDR chunk declaring ``width`` x ``height``, then junk."""
    import struct
    import zlib
    ihdr = struct.pack('>IIBBBBB', width, height, 8, 2, 0, 0, 0)
    chunk = b'IHDR' + ihdr
    return (b'\x89PNG\r\n\x1a\n' + struct.pack('>I', len(ihdr)) + chunk
            + struct.pack('>I', zlib.crc32(chunk)) + bytes(196_000))


class _Logger:
    def __init__(self):
        self.lines = []

    def warning(self, text, **_):
        self.lines.append(text)

    warn = warning

    def info(self, text, **_):
        pass

    error = info


def test_d8_oversized_compressed_image_refused_before_decoding(node_context, tmp_path,
                                                                monkeypatch):
    import time

    from mbtrack_ros.recording import images
    node = _node(node_context, tmp_path, 'rescale_images:=true')
    decoded = []
    real = images.cv2.imdecode
    monkeypatch.setattr(images.cv2, 'imdecode',
                        lambda *a, **k: decoded.append(1) or real(*a, **k))
    try:
        msgs = [_compressed(_png_header(8192, 8192), 10 ** 9 + k) for k in range(15)]
        t0 = time.perf_counter()
        for msg in msgs:
            node._on_image('cam0', msg)
        spent = time.perf_counter() - t0
        assert decoded == [] and node._dropped == 15
        assert spent < 1.0  # 15 messages, no decode: milliseconds
        # a PNG of the calibrated size is still decoded
        from mbtrack_ros.recording.images import encode_compressed
        _, data = encode_compressed(np.zeros((120, 160, 3), np.uint8), 'png')
        node._on_image('cam0', _compressed(data, 2 * 10 ** 9))
        assert decoded == [1] and node._dropped == 15
    finally:
        node.destroy_node()


def test_d5_each_bad_image_cause_logged_once_per_camera(node_context, tmp_path):
    from mbtrack_ros.recording.images import encode_compressed
    node = _node(node_context, tmp_path)
    logger = _Logger()
    node.get_logger = lambda: logger
    good = np.zeros((120, 160, 3), np.uint8)
    t = 10 ** 9

    def raw(**fields):
        msg = _raw(good, t)
        for key, value in fields.items():
            setattr(msg, key, value)
        return msg

    _, jpeg = encode_compressed(good, 'jpeg')
    _, small_png = encode_compressed(np.zeros((60, 80, 3), np.uint8), 'png')
    bad = [
        raw(encoding='yuv422'),                                   # encoding
        raw(height=0),                                            # empty
        raw(width=9000),                                          # too-large
        raw(width=80, step=240),                                  # size-mismatch
        raw(step=10),                                             # step
        raw(data=bytes(10)),                                      # data-length
        _compressed(jpeg, t, fmt='tiff'),                         # format
        _compressed(b'', t),                                      # no-data
        _compressed(b'\x00' * 64, t),                             # no-header
        _compressed(_png_header(160, 120)[:200], t),              # undecodable
        raw(header=_raw(good, t, 'elsewhere').header),            # frame-id
        raw(header=_raw(good, 0).header),                         # stamp
    ]
    assert node._dropped == 0
    for _ in range(3):  # repeated: still one line per cause
        for msg in bad:
            node._on_image('cam0', msg)
    node._on_image('cam0', _compressed(small_png, t))  # size-mismatch again, compressed
    assert node._dropped == 3 * len(bad) + 1
    causes = [line.split('(')[1].split(')')[0] for line in logger.lines]
    assert len(logger.lines) == len(bad), logger.lines
    assert len(set(causes)) == len(bad)
    assert all(line.startswith('cam0: dropping image') for line in logger.lines)
    node._on_image('cam1', raw(encoding='yuv422', header=_raw(good, t,
                                                              'cam1_optical_frame').header))
    assert len(logger.lines) == len(bad) + 1  # another camera, same cause: logged


def test_d6_unexpected_frame_id_dropped_and_counted(node_context, tmp_path):
    node = _node(node_context, tmp_path)
    try:
        rgb = np.zeros((120, 160, 3), np.uint8)
        node._on_image('cam0', _raw(rgb, 10 ** 9, 'cam1_optical_frame'))
        assert node._dropped == 1 and sum(node.sync.pending.values()) == 0
        node._on_image('cam0', _raw(rgb, 10 ** 9))
        assert node._dropped == 1 and sum(node.sync.pending.values()) == 1
        from mbtrack_ros.core.state import FrameResult
        assert node.snapshot(FrameResult(stamp_ns=0)).bad_images == 1
    finally:
        node.destroy_node()


def test_d7_diagnostics_published_while_no_frame_set_forms(node_context, tmp_path):
    import time
    node = _node(node_context, tmp_path, 'diagnostics_period:=0.2', step_thread=True)
    sent = []
    publish = node.pub_diag.publish
    node.pub_diag.publish = lambda msg: sent.append(msg) or publish(msg)
    try:
        rgb = np.zeros((120, 160, 3), np.uint8)
        bad = _raw(rgb, 10 ** 9)
        bad.encoding = 'yuv422'
        deadline = time.monotonic() + 1.5
        k = 0
        while time.monotonic() < deadline:
            node._on_image('cam0', bad)
            node._on_image('cam1', _raw(rgb, 0, 'cam1_optical_frame'))  # stamp 0
            k += 2
            time.sleep(0.02)
        deadline = time.monotonic() + 5.0  # after the feeding: 'no images received'
        while time.monotonic() < deadline and not (
                sent and 'no images received' in sent[-1].status[0].message):
            time.sleep(0.05)
        assert len(sent) >= 3  # ~every 0.2 s of wall-clock time, no frame set formed
        values = {kv.key: kv.value for kv in sent[-1].status[0].values}
        assert int(values['dropped images (bad)']) == k
        reasons = [m.status[0].message for m in sent]
        assert any('refused as bad' in r for r in reasons), reasons
        assert 'no images received' in reasons[-1]  # after the feeding stopped
        from diagnostic_msgs.msg import DiagnosticStatus
        assert all(m.status[0].level == DiagnosticStatus.WARN for m in sent)
    finally:
        node.destroy_node()


def test_d16_rate_window_bounded_under_repeated_stamps(node_context, tmp_path):
    from mbtrack_ros.nodes.tracker_node import RATE_WINDOW_MAX
    node = _node(node_context, tmp_path)
    try:
        rgb = np.zeros((120, 160, 3), np.uint8)
        msg = _raw(rgb, 10 ** 9)
        for _ in range(3 * RATE_WINDOW_MAX):
            node._on_image('cam0', msg)  # cam1 silent: no frame set forms
        assert len(node._rate_window['cam0']) <= RATE_WINDOW_MAX
        assert sum(node.sync.pending.values()) <= node.sync.max_queue
    finally:
        node.destroy_node()


def test_d4_node_drops_a_frame_set_with_the_last_processed_stamp(node_context, tmp_path):
    from mbtrack_ros.recording.sync import FrameSet
    node = _node(node_context, tmp_path)
    seen = []
    process = node.process
    node.process = lambda fs: seen.append(fs.stamp_ns) or process(fs)
    try:
        rgb = np.zeros((120, 160, 3), np.uint8)
        images = {'cam0': rgb, 'cam1': rgb}
        stamps = {'cam0': 10 ** 9, 'cam1': 10 ** 9}
        with node._lock:
            node._pending.extend([FrameSet(0, 10 ** 9, images, stamps),
                                  FrameSet(1, 10 ** 9, images, stamps)])
        node.process_pending()
        assert seen == [10 ** 9]
        from mbtrack_ros.core.state import FrameResult
        snap = node.snapshot(FrameResult(stamp_ns=0))
        assert snap.dropped_sets_repeated == 1
    finally:
        node.destroy_node()


# -- D9: the Fast DDS profile file ------------------------------------------------------------

def test_d9_fastdds_profile_created_safely(tmp_path, monkeypatch):
    import stat

    from mbtrack_ros.nodes import transport
    monkeypatch.setattr('tempfile.tempdir', str(tmp_path))
    monkeypatch.setattr(transport, '_written', None, raising=False)
    uid, pid = os.getuid(), os.getpid()
    # another user's file at the old predictable name, with the expected content
    planted = tmp_path / f'mbtrack_fastdds_{uid}.xml'
    planted.write_text(transport.fastdds_profile())
    # and a symbolic link at the old predictable temporary name
    victim = tmp_path / 'victim.txt'
    victim.write_text('precious')
    (tmp_path / f'mbtrack_fastdds_{uid}.{pid}.tmp').symlink_to(victim)
    planted.unlink()
    (tmp_path / f'mbtrack_fastdds_{uid}.xml').symlink_to(victim)
    env = {}
    path = transport.use_large_shm_segment(env)
    assert victim.read_text() == 'precious'  # no link followed, nothing overwritten
    assert path is not None and env['FASTRTPS_DEFAULT_PROFILES_FILE'] == str(path)
    assert path.parent.parent == tmp_path and path.parent.name != tmp_path.name
    info = path.lstat()
    assert stat.S_ISREG(info.st_mode) and info.st_uid == uid
    assert stat.S_IMODE(info.st_mode) == 0o600
    assert stat.S_IMODE(path.parent.lstat().st_mode) == 0o700
    assert path.read_text() == transport.fastdds_profile()
    # a second call in this process reuses its own file; a replaced file is not trusted
    assert transport.use_large_shm_segment({}) == path
    path.unlink()
    path.symlink_to(victim)
    again = transport.use_large_shm_segment({})
    assert again != path and again.read_text() == transport.fastdds_profile()
    assert victim.read_text() == 'precious'


def test_d8_replay_refuses_oversized_images_before_decoding(recording, tmp_path, capsys,
                                                             monkeypatch):
    """The replay's reader checks each image's declared size against the calibration (at
    most MAX_RESCALE times larger per side) before decoding: a small PNG declaring
    8192x8192 is counted as undecodable, never decoded."""
    import shutil

    from mbtrack_ros.recording import images
    from mbtrack_ros.recording.bag import COMPRESSED, RecordingReader, RecordingWriter, \
        _header, _T, typestore
    dst = tmp_path / 'rec'
    shutil.copytree(recording, dst, ignore=shutil.ignore_patterns('bag'))
    calib = RoomCalibration.load(recording / 'calibration.yaml')
    with RecordingReader(recording) as reader:
        sets = [(fs.stamp_ns, dict(fs.images)) for fs in reader.frames()]
    cam = calib.names[0]
    with RecordingWriter(dst / 'bag', calib, compressed=True) as writer:
        for k, (stamp, imgs) in enumerate(sets):
            if k in (4, 7):
                msg = _T[COMPRESSED](header=_header(stamp, calib.cameras[cam].frame_id),
                                     format='png', data=np.frombuffer(
                                         _png_header(8192, 8192), np.uint8))
                writer._writer.write(writer._image_conn[cam], stamp,
                                     typestore.serialize_cdr(msg, COMPRESSED))
            else:
                writer.write_frame(stamp, imgs)
    assert _replay(dst, tmp_path / 'out') == 0
    err = capsys.readouterr().err
    assert 'dropped 2 undecodable image(s)' in err and 'more than 4 times' in err
    # the replay's reader, with the replay's limit, never hands the oversized payloads to
    # the decoder
    big = []
    real = images.cv2.imdecode
    monkeypatch.setattr(images.cv2, 'imdecode', lambda buf, *a: big.append(buf.size > 150_000)
                        or real(buf, *a))
    with RecordingReader(dst) as reader:
        reader.limit_image_sizes({n: (c.width, c.height) for n, c in calib.cameras.items()})
        errors = [fs.errors for fs in reader.frames()]
    assert sum(len(e) for e in errors) == 2 and big and not any(big)


def test_bag_player_reports_a_skipped_chunk(recording, tmp_path, capsys):
    from mbtrack_ros.nodes import bag_player
    rec = _damage_chunk(recording, tmp_path / 'rec')
    code = bag_player.main(['bag_player', '--ros-args', '-p', f'bag:={rec}',
                            '-p', 'rate:=100.0', '-p', 'start_delay:=0.0'])
    err = capsys.readouterr().err
    assert code == 1 and 'messages unreadable' in err, err


def test_soak_bad_images_are_each_refused(node_context, tmp_path):
    """Every kind of bad image the soak injects (raw and compressed) is refused and counted
    by the node, so the soak's injected count must equal the node's count."""
    from mbtrack_ros.commands.bench_live import BAD_KINDS, bad_image
    node = _node(node_context, tmp_path)
    try:
        for k, kind in enumerate(BAD_KINDS):
            for compressed in (False, True):
                before = node._dropped
                node._on_image('cam0', bad_image(kind, 10 ** 9 + k, 'cam0', 160, 120,
                                                 compressed=compressed))
                assert node._dropped == before + 1, (kind, compressed)
    finally:
        node.destroy_node()


def test_lost_frame_sets_named_by_their_stamp_gaps():
    from mbtrack_ros.recording.bag import _gaps
    text = _gaps([0, 10, 20, 50, 60, 70, 100])
    assert 'between frame sets 2 and 3 (stamps 20 .. 50, ~2 lost)' in text
    assert 'between frame sets 5 and 6 (stamps 70 .. 100, ~2 lost)' in text
    assert 'after frame set 2' in _gaps([0, 10, 20])
