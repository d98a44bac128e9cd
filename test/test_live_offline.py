"""Live replay over DDS and offline replay of the same bag give the same tracks; the live
benchmark's latency helper."""
from __future__ import annotations

import os
import threading
import time
from pathlib import Path

import numpy as np
import pytest

# a domain of our own, before any rclpy context creates a participant
os.environ['ROS_DOMAIN_ID'] = str(150 + os.getpid() % 70)
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'

from conftest import playing  # noqa: E402
from mbtrack_ros.commands.bench_live import (  # noqa: E402
    LatencyError, latency_stats, match_latencies)

SEED = 5
FRAMES = 60  # clear-room at 160x120: the automatic detection starts tracks from frame ~40


# -- latency helper (pure) ---------------------------------------------------------------
def test_match_latencies_pairs_by_stamp_and_counts_missing():
    images = {10: 1.000, 20: 1.100, 30: 1.200, 40: 1.300}
    people = {20: 1.130, 10: 1.020, 40: 1.390, 99: 5.0}  # 30 never answered, 99 not an image
    stamps, lat, missing = match_latencies(images, people)
    assert stamps.tolist() == [10, 20, 40]
    np.testing.assert_allclose(lat, [0.020, 0.030, 0.090])
    assert missing == 1


def test_latency_stats_against_sorted_brute_force():
    rng = np.random.default_rng(3)
    stamps = np.arange(200) * 66_666_667
    t_img = 100.0 + stamps / 1e9 + rng.uniform(0, 0.003, 200)
    lat = rng.gamma(2.0, 0.01, 200)
    images = dict(zip(stamps.tolist(), t_img.tolist()))
    people = {int(s): float(t + d) for s, t, d in zip(stamps[5:], t_img[5:], lat[5:])}
    stats = latency_stats(images, people)
    ref = np.sort(lat[5:])
    n = ref.size
    # nearest-rank percentiles, computed by hand on the sorted list
    assert stats.p50 == pytest.approx(ref[int(np.ceil(0.50 * n)) - 1])
    assert stats.p95 == pytest.approx(ref[int(np.ceil(0.95 * n)) - 1])
    assert stats.max == pytest.approx(ref[-1]) and stats.mean == pytest.approx(ref.mean())
    assert stats.matched == n and stats.missing == 5


def test_latency_stats_refuses_no_overlap_and_negative_latency():
    with pytest.raises(LatencyError, match='no frame'):
        latency_stats({1: 0.0}, {2: 0.1})
    with pytest.raises(LatencyError, match='before'):
        latency_stats({1: 1.0, 2: 2.0}, {1: 1.1, 2: 1.5})


def test_cpu_seconds_reads_proc_like_os_times():
    from mbtrack_ros.commands.bench_live import cpu_seconds
    x = 0.0
    for i in range(300_000):  # burn a little CPU so that both clocks move
        x += i ** 0.5
    t = os.times()
    assert abs(cpu_seconds(os.getpid()) - (t.user + t.system)) < 0.05


def test_thread_cpu_seconds_name_the_thread_that_burnt_the_cpu():
    """Per-thread CPU (/proc/<pid>/task): a Python thread that burns CPU shows in
    ``python threads`` of :func:`thread_split`, the main thread in ``main``; the live
    threads' times never exceed the process's (which keeps the ended threads' too)."""
    import threading

    from mbtrack_ros.commands.bench_live import cpu_seconds, thread_cpu_seconds, thread_split

    def burn():
        x = 0.0
        for i in range(5_000_000):
            x += i ** 0.5

    def work(done: threading.Event):
        burn()
        done.set()
        release.wait(30)

    release, done = threading.Event(), threading.Event()
    before = thread_cpu_seconds(os.getpid())
    worker = threading.Thread(target=work, args=(done,))
    worker.start()
    try:
        done.wait(30)
        after = thread_cpu_seconds(os.getpid())
        total = cpu_seconds(os.getpid())
    finally:
        release.set()
        worker.join()
    split = dict(thread_split(before, after, os.getpid()))
    assert split['python threads'] > 0.05 and split['main'] < split['python threads']
    assert sum(after.values()) <= total + 0.05
    before = thread_cpu_seconds(os.getpid())
    burn()
    split = dict(thread_split(before, thread_cpu_seconds(os.getpid()), os.getpid()))
    assert split['main'] > 0.05 and split.get('python threads', 0.0) < split['main']


def test_bench_live_bad_frames_is_a_one_line_error(capsys):
    from mbtrack_ros.cli import main
    assert main(['bench', '--live', '--live-frames', '5']) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ['mbtrack bench: error: --live-frames must be >= 30, got 5']


@pytest.mark.parametrize('param', ['tracker.pipeline_search=true', ':=1'])
def test_bench_live_bad_node_param_is_a_one_line_error(capsys, param):
    from mbtrack_ros.cli import main
    assert main(['bench', '--live', '--live-param', param]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f'mbtrack bench: error: --live-param must be NAME:=VALUE, got {param!r}']


# -- live vs offline ---------------------------------------------------------------------
@pytest.fixture(scope='module')
def recording(tmp_path_factory) -> Path:
    from mbtrack_ros.synth.generator import generate
    return generate('clear-room', tmp_path_factory.mktemp('rec') / 'room', seed=1,
                    frames=FRAMES, width=160, height=120)


def offline_tracks(recording: Path, out: Path, seed: int, *, pipeline_search: bool = False
                   ) -> dict[int, dict[int, tuple]]:
    """stamp -> {track id: (x, y)} from `mbtrack replay` (automatic detection)."""
    from mbtrack_ros.cli import main
    from mbtrack_ros.recording.csvfiles import read_tracks

    extra = ['--pipeline-search'] if pipeline_search else []
    assert main(['replay', str(recording), '--out', str(out), '--seed', str(seed),
                 *extra]) == 0
    tracks: dict[int, dict[int, tuple]] = {}
    for r in read_tracks(out / 'tracks.csv'):
        tracks.setdefault(r.stamp_ns, {})[r.track_id] = (r.x, r.y)
    return tracks


def live_tracks(recording: Path, seed: int, *, sync_timeout: float = 5.0,
                pipeline_search: bool = False) -> tuple[dict[int, dict[int, tuple]], dict]:
    """bag_player (own process) -> DDS -> tracker_node (in process) -> DDS -> ~/tracks."""
    import rclpy
    from rclpy.context import Context
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import PointCloud2

    from mbtrack_ros.nodes.conversions import stamp_to_ns
    from mbtrack_ros.nodes.messages import tracks_dtype
    from mbtrack_ros.nodes.tracker_node import TrackerNode
    from mbtrack_ros.recording.bag import RecordingReader

    with RecordingReader(recording / 'bag') as reader:
        last = max(fs.stamp_ns for fs in reader.frames())
        cameras = list(reader.cameras)
    context = Context()
    rclpy.init(context=context)
    got: dict[int, dict[int, tuple]] = {}
    lock = threading.Lock()
    try:
        node = TrackerNode(context=context, cli_args=[
            '--ros-args', '-p', f'calibration_file:={recording / "calibration.yaml"}',
            '-p', f'tracker.seed:={seed}', '-p', 'detection.enabled:=true',
            # reliable images, no queue overflow, and a long sync timeout: sync.timeout is
            # message time, but a callback thread of this process can stall for a moment
            # (GIL, first numba compilation) while another camera runs 3 frames ahead; the
            # set would then go out incomplete and the tracks differ from the offline replay
            '-p', 'image_reliability:=reliable', '-p', 'max_pending_sets:=100',
            # ~/tracks kept for a listener that lags (it shares the executor): with depth
            # 10 one run under load received 56 of 60 messages
            '-p', 'qos_depth:=100',
            '-p', 'use_sim_time:=true', '-p', f'sync.timeout:={sync_timeout}',
            '-p', f'tracker.pipeline_search:={str(pipeline_search).lower()}'])
    except Exception:
        rclpy.try_shutdown(context=context)
        raise
    dtype = tracks_dtype(node.params.camera_names)
    listener = rclpy.create_node('live_offline_listener', context=context)

    def on_tracks(msg: PointCloud2) -> None:
        pts = np.frombuffer(bytes(msg.data), dtype=dtype)
        with lock:
            got[stamp_to_ns(msg.header.stamp)] = {
                int(p['id']): (float(p['x']), float(p['y'])) for p in pts}

    listener.create_subscription(PointCloud2, '/tracker_node/tracks', on_tracks,
                                 QoSProfile(depth=500, reliability=ReliabilityPolicy.RELIABLE))
    try:
        with playing(recording, [node, listener], context, rate=0.5,
                     timeout=90):
            # the node may still be working through the sets the player sent at its rate
            # (on a slow machine tens of seconds): wait for the last one, within a bound
            deadline = time.monotonic() + 180
            while time.monotonic() < deadline:
                with lock:
                    if last in got:
                        break
                time.sleep(0.1)
            counters = {'dropped_sets': node._dropped_sets, 'dropped_frames': node._dropped,
                        'incomplete': node.sync.counters.incomplete, 'resets': node._resets,
                        'missing': dict(node.sync.counters.missing)}
    finally:
        rclpy.try_shutdown(context=context)
    return got, counters


@pytest.mark.ros
@pytest.mark.parametrize('pipeline_search', [False, True])
def test_live_replay_equals_offline_replay(recording, tmp_path, pipeline_search):
    """Same bag, same seed: every frame set arrives live, and per stamp the live ~/tracks
    have the same ids as `mbtrack replay` with positions within 1 cm (also with the search
    pipelined on the worker thread: its people are added at a fixed point of the step)."""
    offline = offline_tracks(recording, tmp_path / 'offline', SEED,
                             pipeline_search=pipeline_search)
    live, counters = live_tracks(recording, SEED, pipeline_search=pipeline_search)
    # every frame set complete and tracked: nothing dropped, nothing timed out, no reset
    assert (counters['dropped_sets'], counters['dropped_frames'], counters['incomplete'],
            counters['resets']) == (0, 0, 0, 0), counters
    assert len(live) == FRAMES, f'{len(live)} ~/tracks messages for {FRAMES} frame sets'
    n_tracked = sum(len(v) for v in offline.values())
    assert n_tracked >= 20, 'the comparison needs tracks (automatic detection found none)'
    worst = 0.0
    for stamp, tracks in live.items():
        want = offline.get(stamp, {})
        assert sorted(tracks) == sorted(want), f'ids at {stamp}: live {sorted(tracks)}, ' \
                                               f'offline {sorted(want)}'
        for tid, (x, y) in tracks.items():
            d = float(np.hypot(x - want[tid][0], y - want[tid][1]))
            worst = max(worst, d)
            assert d < 0.01, f'track {tid} at {stamp}: live and offline {d:.3f} m apart'
    assert set(offline) <= set(live)
    print(f'live == offline: {len(live)} frame sets, {n_tracked} track points, '
          f'largest position difference {worst * 1e3:.2f} mm')


@pytest.mark.ros
def test_live_replay_differs_with_another_seed(recording, tmp_path):
    """The comparison above can fail: another offline seed moves the tracks by more than
    1 cm somewhere (so equal seeds, not luck, make them agree)."""
    a = offline_tracks(recording, tmp_path / 'a', SEED)
    b = offline_tracks(recording, tmp_path / 'b', SEED + 1)
    diffs = [np.hypot(a[s][t][0] - b[s][t][0], a[s][t][1] - b[s][t][1])
             for s in a if s in b for t in a[s] if t in b[s]]
    assert diffs and max(diffs) > 0.01


@pytest.mark.parametrize('profile', ['FAST_PROFILE', 'OFFLINE_PROFILE'])
def test_bench_offline_speed_runs_the_profiles(recording, capsys, profile):
    """`mbtrack bench --live` also times the offline replay with the fast and the offline
    profiles: the parameter file reaches the replay (fewer particles in the replay's own
    line)."""
    from mbtrack_ros.commands import bench_live

    params = getattr(bench_live, profile)
    fast = bench_live.run_offline(recording, seed=SEED, params=params)
    assert fast['frames'] == FRAMES and fast['params'] == str(params)
    assert '(hjs, N=50)' in capsys.readouterr().err  # the profile's particle count
    assert fast['cpu_seconds'] > 0
    assert fast['x_real_time'] == pytest.approx(FRAMES / fast['wall_seconds'] / 15.0)


# -- soak (bench --live --live-bad-rate) ----------------------------------------------------
def test_memory_growth_of_a_series():
    from mbtrack_ros.commands.bench_live import memory_growth
    flat = [(float(t), 500.0) for t in range(100)]
    assert memory_growth(flat) == 0.0
    leak = [(float(t), 500.0 + t) for t in range(100)]
    assert memory_growth(leak) == pytest.approx((500 + 94.5) / (500 + 14.5) - 1)
    assert np.isnan(memory_growth(flat[:10]))


@pytest.mark.ros
def test_short_soak_counts_every_injected_bad_image(recording):
    """A short soak: bad images on cam0 for a fifth of the frame sets; the node refuses
    each (counted once in /diagnostics), and every frame set is still processed."""
    from mbtrack_ros.commands.bench_live import BAD_KINDS, run_live, soak_summary
    live = run_live(recording, seed=SEED, bad_rate=0.2, bad_camera='cam0',
                    node_args=('-p', 'warm_up:=false'), timeout=300.0)
    assert live.injected_bad == int(FRAMES * 0.2) >= len(BAD_KINDS)
    d = live.diagnostics
    assert int(d['dropped images (bad)']) == live.injected_bad
    assert int(d['frame sets']) + int(d['incomplete frame sets']) == FRAMES
    assert int(d['dropped frame sets (queue full)']) == 0
    assert live.people_messages == FRAMES
    assert len(live.rss_mb) >= 3 and all(mb > 50 for _, mb in live.rss_mb)
    text = soak_summary(live, 'cam0')
    assert f'frame sets processed {FRAMES} of {FRAMES}' in text
    assert f'injected on cam0: {live.injected_bad}; /diagnostics dropped images (bad): ' \
           f'{live.injected_bad}' in text


def test_live_with_camera_nodes_sending_jpeg_answers_every_frame_set(recording):
    """``bench --live --live-camera-nodes --live-image-format jpeg --live-cameras 2``: two
    camera_node processes send JPEG working images to the fusion tracker_node, which
    answers every frame set; the bench measures the JPEG bytes (a fraction of the raw
    image's) and splits the tracker's CPU by thread."""
    from mbtrack_ros.commands.bench_live import run_live
    live = run_live(recording, seed=SEED, camera_nodes=True, image_format='jpeg', cameras=2,
                    node_args=('-p', 'warm_up:=false'), timeout=300.0)
    assert live.cameras == 2 and len(live.camera_node_cpu_seconds) == 2
    assert all(c > 0 for c in live.camera_node_cpu_seconds)
    assert live.people_messages == FRAMES
    assert 0 < live.image_bytes_per_frame < 0.5 * 160 * 120 * 3
    threads = dict(live.tracker_threads)
    assert threads['main'] > 0 and threads['python threads'] > 0
