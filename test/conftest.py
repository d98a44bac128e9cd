"""Shared fixtures: a small calibrated room that needs no data files; a bag played to
nodes over DDS."""
from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from mbtrack_ros.core.camera import Camera, RoomCalibration, look_at


def make_room(width: int = 160, height: int = 120, n_cameras: int = 2) -> RoomCalibration:
    """A 6 x 5 m room with corner cameras 2.6 m high looking at its centre."""
    corners = [(0.1, 0.1), (5.9, 4.9), (5.9, 0.1), (0.1, 4.9)]
    f = 0.9 * width
    cams = {}
    for i, (x, y) in enumerate(corners[:n_cameras]):
        R, t = look_at((x, y, 2.6), (3.0, 2.5, 0.9))
        cams[f'cam{i}'] = Camera(f'cam{i}', width, height,
                                 [[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1]],
                                 [-0.12, 0.02, 0.0, 0.0, 0.0], R, t)
    return RoomCalibration(cams, (0.0, 0.0, 6.0, 5.0), entry_zones=((0.0, 2.0, 0.6, 3.0),))


@pytest.fixture
def room() -> RoomCalibration:
    return make_room()


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(1234)


REPO = Path(__file__).resolve().parents[1]


@pytest.fixture
def context():
    """A fresh rclpy context for one test's nodes (shut down after it)."""
    import rclpy
    from rclpy.context import Context

    ctx = Context()
    rclpy.init(context=ctx)
    yield ctx
    rclpy.try_shutdown(context=ctx)


@contextmanager
def spinning(nodes: list, context):
    """Dispatch the callbacks of ``nodes`` on a thread of their own with the tracker
    node's executor (``make_executor('events')``, as ``tracker_node`` spins) until the
    block ends. (The Python ``MultiThreadedExecutor`` rebuilds its wait set in a loop that
    holds the GIL and starves an in-process tracker's step thread.)"""
    from mbtrack_ros.nodes.tracker_node import make_executor

    executor = make_executor('events', context=context)
    for node in nodes:
        executor.add_node(node)
    stop = threading.Event()

    def spin() -> None:
        while not stop.is_set() and context.ok():
            executor.spin_once(timeout_sec=0.1)

    spinner = threading.Thread(target=spin, daemon=True)
    spinner.start()
    try:
        yield executor
    finally:
        stop.set()
        spinner.join(timeout=5)
        executor.shutdown()


@contextmanager
def playing(recording: Path, nodes: list, context, *, rate: float,
            timeout: float, topics: list[str] | None = None, ready=None):
    """Spin ``nodes`` (:func:`spinning`) while ``bag_player`` (its own process)
    plays ``recording`` at ``rate`` (only ``topics`` if given); yields once the player has
    finished (its exit code is checked). ``ready`` (no argument, returns bool), if given, is
    polled for up to 60 s before the player starts: DDS discovery of the test's subscriptions
    takes its time on a loaded machine, and messages published before it are lost. On exit:
    player killed if still running, executor stopped, nodes destroyed."""
    try:
        with spinning(nodes, context):
            if ready is not None:
                deadline = time.monotonic() + 60
                while not ready():
                    assert time.monotonic() < deadline, 'the test subscriptions never matched'
                    time.sleep(0.1)
            player = subprocess.Popen(
                [sys.executable, '-m', 'mbtrack_ros.nodes.bag_player', '--ros-args',
                 '-p', f'bag:={recording}', '-p', f'rate:={rate}',
                 '-p', 'wait_for_subscribers:=true', '-p', 'start_delay:=1.0']
                + (['-p', f'topics:=[{", ".join(topics)}]'] if topics else []),
                cwd=REPO, env=dict(os.environ, PYTHONPATH=str(REPO)), stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT, text=True)
            try:
                out, _ = player.communicate(timeout=timeout)
                assert player.returncode == 0, out
                yield
            finally:
                if player.poll() is None:
                    player.kill()
    finally:
        for node in nodes:
            node.destroy_node()


def write_bag(path: Path, messages, compressed_chunks: bool = False) -> Path:
    """A rosbag2 MCAP bag at ``path`` of ``messages`` [(topic, msg, log time ns)], written in
    that order (zstd-compressed chunks with ``compressed_chunks``)."""
    from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

    from mbtrack_ros.recording.bag import typestore
    writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
    if compressed_chunks:
        writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    conns = {}
    with writer:
        for topic, msg, t in messages:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msg.__msgtype__,
                                                     typestore=typestore)
            writer.write(conns[topic], t, typestore.serialize_cdr(msg, msg.__msgtype__))
    return path
