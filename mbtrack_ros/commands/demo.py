"""``mbtrack demo``: the whole system on a synthetic smart room, through real ROS 2 nodes.

1. generate (or reuse) a ``clear-room`` recording with ground truth;
2. start ``tracker_node`` and ``bag_player`` as separate processes talking over DDS, the
   player publishing the recording in real time with ``/clock`` (the tracker uses sim time);
3. listen to ``/tracker_node/tracks`` like any ROS consumer would, showing live progress;
4. score the received tracks (CLEAR MOT) and write the plots and a picture of the views.

Everything lands in ``--out`` (default ``mbtrack-demo/``). ``--offline`` runs the same
tracker in-process over the bag instead of through the nodes (as fast as the machine allows).
"""
from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import yaml

__all__ = ['add_parser', 'run']


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(
        'demo', help='generate a smart-room recording, track it through the ROS 2 nodes, '
                     'score it',
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--out', type=Path, default=Path('mbtrack-demo'),
                        help='output directory (default: mbtrack-demo)')
    parser.add_argument('--preset', default='clear-room', help='synth preset (clear-room)')
    parser.add_argument('--frames', type=int, default=450,
                        help='frames to generate (default 450 = 30 s at 15 Hz)')
    parser.add_argument('--seed', type=int, default=1, help='recording and tracker seed')
    parser.add_argument('--rate', type=float, default=0.5,
                        help='playback rate factor (default 0.5: half real time, so that a '
                             '2-core machine keeps up with detection on five cameras; '
                             '1.0 = real time)')
    parser.add_argument('--init-from-ground-truth', action='store_true',
                        help='start tracks from the ground truth instead of detecting people')
    parser.add_argument('--offline', action='store_true',
                        help='run the tracker in-process over the bag (no DDS)')
    return parser


def _say(message: str) -> None:
    print(f'mbtrack demo: {message}', file=sys.stderr, flush=True)


def _ensure_recording(args: argparse.Namespace) -> Path:
    """Reuse ``OUT/recording`` if it was made with the same settings, else generate it."""
    from mbtrack_ros.synth.generator import generate

    rec = args.out / 'recording'
    meta = rec / 'recording.yaml'
    if meta.exists():
        try:
            info = yaml.safe_load(meta.read_text())
            if (info.get('preset'), info.get('seed'), info.get('frames')) == (
                    args.preset, args.seed, args.frames) and (rec / 'bag').exists():
                _say(f'reusing the recording in {rec}')
                return rec
        except (OSError, yaml.YAMLError):
            pass
        import shutil
        shutil.rmtree(rec)
    _say(f'generating a {args.frames}-frame {args.preset} recording in {rec}')
    generate(args.preset, rec, seed=args.seed, frames=args.frames, progress=True)
    return rec


class _TrackListener:
    """A plain ROS consumer of ``~/tracks`` (PointCloud2) that collects track rows."""

    def __init__(self, cameras: list[str], stamp_to_frame) -> None:
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import PointCloud2

        from mbtrack_ros.nodes.messages import tracks_dtype

        self.dtype = tracks_dtype(cameras)
        self.stamp_to_frame = stamp_to_frame
        self.rows = []
        self.messages = 0
        self.stamps: set[int] = set()
        self.heights: dict[tuple[int, int], float] = {}
        self.last_stamp = 0
        self.last_arrival = time.monotonic()
        self.tracks_now = 0
        self.diagnostics: dict[str, str] = {}
        self._lock = threading.Lock()
        self.node = rclpy.create_node('mbtrack_demo_listener')
        qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        self.node.create_subscription(PointCloud2, '/tracker_node/tracks', self._on_tracks, qos)
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics, qos)

    def _on_diagnostics(self, msg) -> None:
        for status in msg.status:
            if status.name.endswith('tracker') or status.name.endswith(': tracker'):
                self.diagnostics = {kv.key: kv.value for kv in status.values}

    def _on_tracks(self, msg) -> None:
        from mbtrack_ros.recording.csvfiles import TrackRow

        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        points = np.frombuffer(bytes(msg.data), dtype=self.dtype, count=msg.width)
        frame = self.stamp_to_frame(stamp)
        with self._lock:
            self.rows.extend(TrackRow(stamp, frame, int(p['id']), float(p['x']), float(p['y']),
                                      float(p['visibility']), float(p['existence']))
                             for p in points)
            self.heights.update({(stamp, int(p['id'])): float(p['height']) for p in points})
            self.messages += 1
            self.stamps.add(stamp)
            self.last_stamp = stamp
            self.tracks_now = int(msg.width)
            self.last_arrival = time.monotonic()


def _node_command(module: str, params: dict[str, object]) -> list[str]:
    cmd = [sys.executable, '-m', f'mbtrack_ros.nodes.{module}', '--ros-args']
    for key, value in params.items():
        if isinstance(value, bool):
            value = str(value).lower()
        cmd += ['-p', f'{key}:={value}']
    return cmd


def _warm_up(rec: Path, calibration_path: Path) -> None:
    """Compile the numba kernels once (cached on disk) so the node starts at full speed."""
    from mbtrack_ros.cli import main as cli_main

    _say('compiling the tracker kernels (first run only)')
    cli_main(['replay', str(rec), '--out', str(rec.parent / '.warmup'), '--max-frames', '3',
              '--config', str(calibration_path),
              '--init-from', str(rec / 'ground_truth.csv')])


def _run_live(args: argparse.Namespace, rec: Path, info: dict
              ) -> tuple[list, list[int], dict[tuple[int, int], float]]:
    """Play the recording through bag_player and tracker_node; collect ``~/tracks``."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from tqdm import tqdm

    env = dict(os.environ)
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')  # keep the demo on this host
    env.setdefault('ROS_DOMAIN_ID', str(60 + os.getpid() % 40))
    os.environ.update({k: env[k] for k in ('ROS_AUTOMATIC_DISCOVERY_RANGE', 'ROS_DOMAIN_ID')})

    epoch, period = int(info['epoch_ns']), 1e9 / float(info['fps'])

    def stamp_to_frame(stamp: int) -> int:
        return int(round((stamp - epoch) / period))

    tracker_params = {
        'calibration_file': rec / 'calibration.yaml', 'use_sim_time': True,
        'output_bag': args.out / 'tracks.mcap', 'tracker.seed': args.seed,
        # a replay may not lose frames: the player publishes reliably, so ask for it
        'image_reliability': 'reliable',
        # and queue as deep as the player does (2 s at 15 Hz): a busy moment of the
        # tracker's callbacks then delays frames instead of losing them
        'qos_depth': 30,
    }
    if args.init_from_ground_truth:
        tracker_params['init_ground_truth'] = rec / 'ground_truth.csv'
    else:
        tracker_params['detection.enabled'] = True
    # the player waits until the tracker subscribes to every camera and to /clock: images
    # published before that are lost, and the tracker would learn its background from
    # later frames with people standing in them
    player_params = {'bag': rec, 'rate': args.rate, 'exit_when_done': True,
                     'start_delay': 1.0, 'wait_for_subscribers': True,
                     'clock_subscribers': 1}
    out_bag = args.out / 'tracks.mcap'
    if out_bag.exists():
        import shutil
        shutil.rmtree(out_bag) if out_bag.is_dir() else out_bag.unlink()

    rclpy.init()
    listener = _TrackListener(list(info['cameras']), stamp_to_frame)
    executor = SingleThreadedExecutor()
    executor.add_node(listener.node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    logs = args.out / 'logs'
    logs.mkdir(parents=True, exist_ok=True)
    tracker = player = None
    try:
        _say('starting tracker_node (ROS 2, sim time)')
        tracker = subprocess.Popen(_node_command('tracker_node', tracker_params), env=env,
                                   stdout=(logs / 'tracker_node.log').open('w'),
                                   stderr=subprocess.STDOUT)
        deadline = time.monotonic() + 60
        while listener.node.count_publishers('/tracker_node/tracks') == 0:
            if tracker.poll() is not None:
                raise RuntimeError(f'tracker_node exited (code {tracker.returncode}); '
                                   f'see {logs / "tracker_node.log"}')
            if time.monotonic() > deadline:
                raise RuntimeError('tracker_node did not come up within 60 s')
            time.sleep(0.2)
        _say(f'starting bag_player at {args.rate:g}x real time')
        player = subprocess.Popen(_node_command('bag_player', player_params), env=env,
                                  stdout=(logs / 'bag_player.log').open('w'),
                                  stderr=subprocess.STDOUT)
        frames = int(info['frames'])
        last_stamp = epoch + int((frames - 1) * period)
        with tqdm(total=frames, unit='frame', desc='tracking (live)') as bar:
            while True:
                time.sleep(0.25)
                done = listener.messages
                bar.n = min(done, frames)
                bar.set_postfix(tracks=listener.tracks_now, refresh=False)
                bar.refresh()
                if listener.last_stamp >= last_stamp:
                    break
                if player.poll() is not None and time.monotonic() - listener.last_arrival > 5:
                    break  # the player is done and nothing more is coming
                if tracker.poll() is not None:
                    raise RuntimeError(f'tracker_node exited (code {tracker.returncode}); '
                                       f'see {logs / "tracker_node.log"}')
        _say(f'the tracker processed {listener.messages} of {frames} frame sets'
             + (f' (tracker_node diagnostics: {listener.diagnostics.get("dropped frames")} '
                'frames dropped because it fell behind; lower --rate on a slow machine)'
                if listener.messages < frames else ''))
    finally:
        for proc in (player, tracker):
            if proc is not None and proc.poll() is None:
                proc.send_signal(signal.SIGINT)
        for proc in (player, tracker):
            if proc is not None:
                try:
                    proc.wait(timeout=20)
                except subprocess.TimeoutExpired:
                    proc.kill()
        executor.shutdown()
        listener.node.destroy_node()
        rclpy.try_shutdown()
    return listener.rows, sorted(listener.stamps), listener.heights


def _run_offline(args: argparse.Namespace, rec: Path) -> list:
    from mbtrack_ros.cli import main as cli_main
    from mbtrack_ros.recording.csvfiles import read_tracks

    cmd = ['replay', str(rec), '--out', str(args.out), '--seed', str(args.seed)]
    if args.init_from_ground_truth:
        cmd += ['--init-from', str(rec / 'ground_truth.csv')]
    if cli_main(cmd) != 0:
        raise RuntimeError('the offline replay failed')
    return read_tracks(args.out / 'tracks.csv')


def run(args: argparse.Namespace) -> int:
    from mbtrack_ros.evaluation import clear_mot
    from mbtrack_ros.evaluation.plots import plot_localisation_error, plot_trajectories
    from mbtrack_ros.evaluation.report import format_table, write_report
    from mbtrack_ros.recording.csvfiles import read_ground_truth, write_tracks
    from mbtrack_ros.synth.preview import contact_sheet

    if args.frames <= 0 or args.rate <= 0:
        print('mbtrack demo: error: --frames and --rate must be positive', file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    started = time.monotonic()
    rec = _ensure_recording(args)
    info = yaml.safe_load((rec / 'recording.yaml').read_text())
    truth = read_ground_truth(rec / 'ground_truth.csv')
    try:
        if args.offline:
            rows, processed_stamps, heights = _run_offline(args, rec), [], {}
        else:
            _warm_up(rec, rec / 'calibration.yaml')
            # heights: (stamp, track id) -> the body height the node published
            rows, processed_stamps, heights = _run_live(args, rec, info)
    except RuntimeError as err:
        print(f'mbtrack demo: error: {err}', file=sys.stderr)
        return 1
    write_tracks(args.out / 'tracks.csv', rows)
    # live: score the frame sets the tracker processed (a dropped set is a speed problem,
    # reported above, not a tracking error); offline every frame is processed
    processed = set(processed_stamps)
    scored = [r for r in truth if r.stamp_ns in processed] if processed else truth
    if len(scored) < len(truth):
        _say(f'scoring the {len(processed)} processed frame sets')
    result = clear_mot(rows, scored, name=f'{args.preset} seed {args.seed}',
                       frame_stamps=sorted(processed) if processed else None)
    images = [plot_trajectories(rows, truth, args.out / 'trajectories.png',
                                title='tracks (colour) vs ground truth (grey)'),
              plot_localisation_error(result, args.out / 'error.png')]
    # a picture of the frame with the most people, tracks drawn over the ground truth
    counts = np.bincount([r.frame for r in truth])
    frame = int(np.argmax(counts))
    stamp = next(r.stamp_ns for r in truth if r.frame == frame)
    drawn = [(r.track_id, r.x, r.y, heights.get((stamp, r.track_id), 1.75))
             for r in rows if r.stamp_ns == stamp]
    images.append(contact_sheet(rec, frame, args.out / 'views.png', tracks=drawn))
    write_report(args.out, [result], images=images,
                 inputs={'recording': str(rec), 'tracks': str(args.out / 'tracks.csv')})
    print(format_table([result]))
    _say(f'done in {time.monotonic() - started:.0f} s; tracks, scores and pictures in '
         f'{args.out}/ (views.png, trajectories.png, error.png, scores.md)')
    return 0
