"""mbtrack replay on a tiny synthetic recording: outputs, evaluation, errors."""
from __future__ import annotations

import csv
import os
import sys

import numpy as np
import pytest

from mbtrack_ros.cli import main
from mbtrack_ros.recording.csvfiles import TRACK_COLUMNS, read_ground_truth, read_tracks


@pytest.fixture(scope='module')
def recording(tmp_path_factory):
    out = tmp_path_factory.mktemp('rec') / 'seq1'
    code = main(['synth', 'lanz-seq1-short', str(out), '--frames', '24', '--width', '160',
                 '--height', '120'])
    assert code == 0
    return out


def _one_error_line(capsys):
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith('mbtrack replay: error: ')
    return err[0]


def test_replay_writes_tracks_and_particles(recording, tmp_path, capsys):
    out = tmp_path / 'out'
    gt = recording / 'ground_truth.csv'
    code = main(['replay', str(recording), '--out', str(out), '--init-from', str(gt),
                 '--eval', str(gt), '--save-particles', '--particles', '40', '--seed', '3'])
    assert code == 0
    captured = capsys.readouterr()
    assert 'MOTA' in captured.out
    with (out / 'tracks.csv').open() as handle:
        header = next(csv.reader(handle))
    assert tuple(header[:5]) == TRACK_COLUMNS
    rows = read_tracks(out / 'tracks.csv')
    truth = read_ground_truth(gt)
    people = {r.person_id for r in truth}
    assert {r.track_id for r in rows} == set(range(1, len(people) + 1))
    assert len(rows) == len(truth)  # every person tracked at every frame
    # tracks start at the ground truth and stay close on this short, easy sequence
    by_stamp = {(r.stamp_ns, r.person_id): r for r in truth}
    first = {r.track_id: r for r in sorted(rows, key=lambda r: r.stamp_ns)}
    for row in first.values():
        near = min(np.hypot(row.x - g.x, row.y - g.y) for (s, _), g in by_stamp.items()
                   if s == row.stamp_ns)
        assert near < 0.3
    data = np.load(out / 'particles.npz')
    assert data['xy'].shape == (len(rows), 40, 2)
    np.testing.assert_allclose(data['weights'].sum(axis=1), 1.0, rtol=1e-5)


def test_max_frames_and_config_default(recording, tmp_path, capsys):
    out = tmp_path / 'out'
    gt = recording / 'ground_truth.csv'
    code = main(['replay', str(recording / 'bag'), '--config',
                 str(recording / 'calibration.yaml'), '--out', str(out), '--init-from',
                 str(gt), '--max-frames', '3', '--algorithm', 'separable', '--particles', '30',
                 '--eval', str(gt)])
    assert code == 0
    rows = read_tracks(out / 'tracks.csv')
    assert len({r.stamp_ns for r in rows}) == 3
    # the evaluation scores only the replayed frames
    table = capsys.readouterr().out.strip().splitlines()
    assert table[-1].split()[-4] == '3'


@pytest.mark.parametrize('argv, needle', [
    (['--algorithm', 'magic'], 'unknown algorithm'),
    (['--particles', '0'], 'particles'),
    (['--particles', 'many'], 'invalid int'),
    (['--max-frames', '0'], 'max-frames'),
])
def test_bad_arguments_exit_2_with_one_line(recording, tmp_path, capsys, argv, needle):
    gt = recording / 'ground_truth.csv'
    with pytest.raises(SystemExit) if needle == 'invalid int' else _nullcontext() as exc:
        code = main(['replay', str(recording), '--out', str(tmp_path / 'o'), '--init-from',
                     str(gt)] + argv)
    if exc is not None and needle == 'invalid int':
        code = exc.value.code
    assert code == 2
    assert needle in _one_error_line(capsys)


class _nullcontext:
    def __enter__(self):
        return None

    def __exit__(self, *exc):
        return False


def test_missing_inputs_exit_2(recording, tmp_path, capsys):
    out = str(tmp_path / 'o')
    assert main(['replay', str(tmp_path / 'nope'), '--out', out]) == 2
    assert 'does not exist' in _one_error_line(capsys)
    assert main(['replay', str(recording / 'bag'), '--out', out, '--init-from',
                 str(recording / 'ground_truth.csv')]) == 2
    assert '--config' in _one_error_line(capsys)
    bad_gt = tmp_path / 'gt.csv'
    bad_gt.write_text('a,b\n1,2\n')
    assert main(['replay', str(recording), '--out', out, '--init-from', str(bad_gt)]) == 2
    assert 'missing column' in _one_error_line(capsys)


def test_corrupt_bag_keeps_tracks_so_far(recording, tmp_path, capsys):
    import shutil

    damaged = tmp_path / 'damaged'
    shutil.copytree(recording, damaged)
    mcap = next((damaged / 'bag').glob('*.mcap'))
    data = mcap.read_bytes()
    mcap.write_bytes(data[: int(len(data) * 0.75)])  # cut the file: last chunk damaged
    out = tmp_path / 'out'
    code = main(['replay', str(damaged), '--out', str(out), '--init-from',
                 str(damaged / 'ground_truth.csv'), '--particles', '30'])
    assert code == 1
    err = capsys.readouterr().err
    assert 'mbtrack replay: error:' in err and 'Traceback' not in err
    rows = read_tracks(out / 'tracks.csv')
    frames = {r.frame for r in rows}
    assert 0 < len(frames) < 24
    assert frames == set(range(len(frames)))  # every frame before the damage was tracked


def test_wrong_image_size_mid_bag_is_one_line_error(recording, tmp_path, capsys):
    import shutil

    import cv2

    from mbtrack_ros.core.camera import RoomCalibration
    from mbtrack_ros.recording.bag import IMAGE, RecordingReader, RecordingWriter, _header, \
        _T, typestore

    rec = tmp_path / 'rec'   # the recording with half-size images in frame set 6
    shutil.copytree(recording, rec, ignore=shutil.ignore_patterns('bag'))
    calib = RoomCalibration.load(recording / 'calibration.yaml')
    with RecordingReader(recording) as reader:
        sets = [(fs.stamp_ns, dict(fs.images)) for fs in reader.frames()]
    with RecordingWriter(rec / 'bag', calib) as writer:
        for k, (stamp, images) in enumerate(sets):
            if k != 6:
                writer.write_frame(stamp, images)
                continue
            for cam, im in images.items():
                half = cv2.resize(im, (im.shape[1] // 2, im.shape[0] // 2))
                msg = _T[IMAGE](header=_header(stamp, calib.cameras[cam].frame_id),
                                height=half.shape[0], width=half.shape[1], encoding='rgb8',
                                is_bigendian=0, step=half.shape[1] * 3, data=half.reshape(-1))
                writer._writer.write(writer._image_conn[cam], stamp,
                                     typestore.serialize_cdr(msg, IMAGE))
    out = tmp_path / 'out'
    code = main(['replay', str(rec), '--out', str(out), '--init-from',
                 str(rec / 'ground_truth.csv'), '--particles', '30'])
    assert code == 1
    err = capsys.readouterr().err
    assert 'Traceback' not in err and 'frame set 6' in err
    assert {r.frame for r in read_tracks(out / 'tracks.csv')} == set(range(6))


class _FailingWriter:
    """A picklable stand-in for OutputBagWriter (built in the writer process)."""

    def __init__(self, fail_at: int) -> None:
        self.fail_at = fail_at

    def write(self, result) -> None:
        if result.stamp_ns == self.fail_at:
            raise OSError('disk full')

    def close(self) -> None:
        pass


def test_background_writer_in_a_process_writes_the_bag_in_order_and_reports_errors(tmp_path):
    """``mbtrack replay`` writes tracks.mcap in a child process: the results arrive in order
    and as they were when handed over; errors of the child are raised in the parent."""
    import functools

    from rosbags.highlevel import AnyReader

    from conftest import make_room
    from mbtrack_ros.commands.output_writer import BackgroundWriter
    from mbtrack_ros.core.state import FrameResult, TrackEstimate
    from mbtrack_ros.nodes.output_bag import OutputBagError, OutputBagWriter

    room = make_room()
    out = tmp_path / 'tracks.mcap'
    writer = BackgroundWriter(functools.partial(OutputBagWriter, out, room), depth=2,
                               process=True)
    mean = np.zeros(6)
    for k in range(20):
        mean[0] = 0.1 * k  # one buffer, overwritten like a tracker reusing its arrays
        writer.write(FrameResult(stamp_ns=k + 1, tracks=[TrackEstimate(
            track_id=1, mean=mean, covariance=np.eye(6), height=1.7)]))
    writer.close()
    with AnyReader([out]) as reader:
        people = [(stamp, reader.deserialize(raw, conn.msgtype).poses[0].position.x)
                  for conn, stamp, raw in reader.messages()
                  if conn.topic == '/tracker_node/people']
    assert people == [(k + 1, pytest.approx(0.1 * k)) for k in range(20)]

    failing = BackgroundWriter(functools.partial(_FailingWriter, 3), depth=2, process=True)
    with pytest.raises(OSError, match='disk full'):
        for k in range(50):
            failing.write(FrameResult(stamp_ns=k))
        failing.close()
    with pytest.raises(OutputBagError, match='already exists'):
        BackgroundWriter(functools.partial(OutputBagWriter, out, room), process=True)
    # started without waiting (replay builds the tracker meanwhile): the error comes with
    # ready(), and a writer discarded before use ends its child and leaves an empty bag
    late = BackgroundWriter(functools.partial(OutputBagWriter, out, room), process=True,
                             wait=False)
    with pytest.raises(OutputBagError, match='already exists'):
        late.ready()
    assert late._child.poll() is not None
    unused = BackgroundWriter(functools.partial(OutputBagWriter, tmp_path / 'unused', room),
                               process=True, wait=False)
    unused.discard()
    assert unused._child.returncode == 0
    with AnyReader([tmp_path / 'unused']) as reader:
        assert not list(reader.messages())


@pytest.mark.skipif(not sys.platform.startswith('linux'), reason='/proc and F_GETPIPE_SZ')
def test_background_writer_child_at_lower_priority_writes_everything(tmp_path):
    """With ``niceness`` the writer child runs that much nicer than the caller, its pipe is
    enlarged (so the tracker's writes do not wait for it), and every result still reaches
    the bag in order."""
    import fcntl
    import functools

    from rosbags.highlevel import AnyReader

    from conftest import make_room
    from mbtrack_ros.commands.output_writer import BackgroundWriter
    from mbtrack_ros.core.state import FrameResult, TrackEstimate
    from mbtrack_ros.nodes.output_bag import OutputBagWriter

    out = tmp_path / 'tracks.mcap'
    writer = BackgroundWriter(functools.partial(OutputBagWriter, out, make_room()),
                              process=True, niceness=5)
    own = os.getpriority(os.PRIO_PROCESS, 0)
    assert os.getpriority(os.PRIO_PROCESS, writer._child.pid) == min(own + 5, 19)
    limit = int(open('/proc/sys/fs/pipe-max-size').read())
    assert fcntl.fcntl(writer._child.stdin.fileno(), 1032) >= min(1 << 20, limit)  # GETPIPE
    for k in range(300):
        writer.write(FrameResult(stamp_ns=k + 1, tracks=[TrackEstimate(
            track_id=1, mean=np.full(6, 0.01 * k), covariance=np.eye(6), height=1.7)]))
    writer.close()
    with AnyReader([out]) as reader:
        stamps = [stamp for conn, stamp, _ in reader.messages()
                  if conn.topic == '/tracker_node/people']
    assert stamps == list(range(1, 301))


def test_background_writer_keeps_order_snapshots_results_and_reports_errors():
    """tracks.mcap is written in a thread: results in order, as they were when handed over
    (the tracker may reuse its arrays), and a write error is raised in the main thread."""
    from mbtrack_ros.commands.output_writer import BackgroundWriter
    from mbtrack_ros.core.state import FrameResult, TrackEstimate

    class Fake:
        def __init__(self, fail_at=None):
            self.got, self.closed, self.fail_at = [], False, fail_at

        def write(self, result):
            if result.stamp_ns == self.fail_at:
                raise OSError('disk full')
            self.got.append((result.stamp_ns, [t.mean[0] for t in result.tracks]))

        def close(self):
            self.closed = True

    mean = np.zeros(6)
    fake = Fake()
    writer = BackgroundWriter(fake, depth=2)
    for k in range(20):
        mean[0] = k  # one buffer, overwritten like a tracker reusing its arrays
        writer.write(FrameResult(stamp_ns=k, tracks=[TrackEstimate(
            track_id=1, mean=mean, covariance=np.eye(4), height=1.7)]))
    writer.close()
    assert fake.closed and fake.got == [(k, [float(k)]) for k in range(20)]

    failing = Fake(fail_at=3)
    writer = BackgroundWriter(failing, depth=2)
    for k in range(6):
        try:
            writer.write(FrameResult(stamp_ns=k))
        except OSError:
            break
    with pytest.raises(OSError, match='disk full'):
        writer.close()
    assert failing.closed and [s for s, _ in failing.got] == [0, 1, 2]


def test_the_replay_command_ends_at_once_with_complete_outputs(recording, tmp_path, capsys):
    """Run as the ``mbtrack`` command, replay ends its process right after its last file is
    closed (no interpreter tear-down, 0.3-0.6 s): the exit code, tracks.csv and
    tracks.mcap are those of the same replay called in-process, also for a damaged bag."""
    import shutil
    import subprocess
    import sys

    from rosbags.highlevel import AnyReader

    damaged = tmp_path / 'damaged'
    shutil.copytree(recording, damaged)
    mcap = next((damaged / 'bag').glob('*.mcap'))
    mcap.write_bytes(mcap.read_bytes()[: int(mcap.stat().st_size * 0.75)])
    # the console script's body, with an exit hook that a quick exit never runs
    script = ('import atexit, sys\n'
              'atexit.register(lambda: print("tear-down ran", file=sys.stderr))\n'
              'from mbtrack_ros.cli import main\n'
              'sys.exit(main())\n')
    for rec, expected_code in ((recording, 0), (damaged, 1)):
        args = ['replay', str(rec), '--init-from', str(rec / 'ground_truth.csv'),
                '--particles', '30', '--seed', '2']
        inside, outside = tmp_path / f'in_{rec.name}', tmp_path / f'out_{rec.name}'
        assert main(args + ['--out', str(inside)]) == expected_code
        capsys.readouterr()
        done = subprocess.run([sys.executable, '-c', script] + args + ['--out', str(outside)],
                              capture_output=True, text=True)
        assert done.returncode == expected_code, done.stderr[-2000:]
        assert 'tear-down ran' not in done.stderr
        assert 'mbtrack replay: ' in done.stderr and 'Traceback' not in done.stderr
        assert (outside / 'tracks.csv').read_bytes() == (inside / 'tracks.csv').read_bytes()
        counts = []
        for out in (inside, outside):
            with AnyReader([out / 'tracks.mcap']) as reader:
                counts.append(sum(1 for _ in reader.messages()))
        assert counts[0] == counts[1] > 0


def test_replay_at_half_scale_resizes_ahead_with_the_same_tracks(recording, tmp_path, capsys,
                                                                 monkeypatch):
    """With ``--working-pixels`` the replay decodes the images at the working size in its
    reader thread (``RecordingReader.decode_to``: the resize of ``Tracker.step``, done
    ahead): the step gets them at its size, and the tracks are those of a replay that
    leaves the resize to the step, bit for bit."""
    from mbtrack_ros.core.tracker import Tracker
    from mbtrack_ros.recording.bag import RecordingReader

    gt = recording / 'ground_truth.csv'
    args = ['replay', str(recording), '--working-pixels', '4800', '--particles', '30',
            '--seed', '4', '--init-from', str(gt)]
    seen = []
    step = Tracker.step

    def recording_step(self, stamp_ns, images, **kwargs):
        seen.append({c: im.shape[:2] for c, im in images.items()})
        return step(self, stamp_ns, images, **kwargs)

    monkeypatch.setattr(Tracker, 'step', recording_step)
    assert main(args + ['--out', str(tmp_path / 'ahead')]) == 0
    assert seen and all(shape == (60, 80) for frame in seen for shape in frame.values())
    monkeypatch.setattr(Tracker, 'step', step)
    monkeypatch.setattr(RecordingReader, 'decode_to', lambda self, cameras: None)
    assert main(args + ['--out', str(tmp_path / 'in_step')]) == 0
    capsys.readouterr()
    ahead = (tmp_path / 'ahead' / 'tracks.csv').read_bytes()
    assert ahead.count(b'\n') > 24  # people tracked
    assert ahead == (tmp_path / 'in_step' / 'tracks.csv').read_bytes()
