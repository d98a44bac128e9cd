"""``bag_player``: publish a rosbag2 recording's topics in (scaled) real time, with ``/clock``.

There is no ``ros2 bag`` on this platform: the bag is read with rosbags and every message is
published as the raw CDR bytes stored in the bag (rclpy publishers accept serialised
messages), so nothing is decoded. Message time comes from the bag's log time; ``/clock``
(rosgraph_msgs/Clock) follows it, so a tracker with ``use_sim_time`` sees bag time: one
``/clock`` message when the bag time advances (before the first message of each stamp; all
messages of a frame set share a stamp), not one per message. The messages of one stamp go out
back to back. Fast DDS gets a shared-memory segment large enough for a burst of images
(:mod:`mbtrack_ros.nodes.transport`).

Parameters: ``bag`` (rosbag2 directory, or a recording directory with ``bag/`` inside;
required), ``rate`` (playback speed factor, 1.0), ``loop`` (restart at the end, false),
``exit_when_done`` (true), ``publish_clock`` (true), ``topics`` (only these; default all),
``start_delay`` (s before the first message, 0.5), ``wait_for_subscribers`` (wait up to
``subscriber_timeout`` s, default 30, until every image topic has a subscriber, false),
``clock_subscribers`` (with ``wait_for_subscribers``, also wait until ``/clock`` has this many
matched subscribers, 0: a tracker with ``use_sim_time`` plus any listener that times
frames by their ``/clock``, so that none misses the first ones).

A damaged bag (truncated MCAP, unreadable chunk) is played up to the damage, as
``mbtrack replay`` reads it; the player then logs the damage and exits with code 1.
"""
from __future__ import annotations

import importlib
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import rclpy
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosbags.highlevel import AnyReader
from rosgraph_msgs.msg import Clock

from mbtrack_ros.nodes.conversions import ns_to_stamp
from mbtrack_ros.nodes.transport import use_large_shm_segment
from mbtrack_ros.recording.bag import BagError, stream_mcap

__all__ = ['BagPlayer', 'PlayerError', 'main', 'message_class']

IMAGE_TYPES = {'sensor_msgs/msg/Image', 'sensor_msgs/msg/CompressedImage'}


class PlayerError(RuntimeError):
    """The bag cannot be played (one-line reason)."""


@dataclass(frozen=True)
class _Connection:
    """A topic of a damaged bag read without rosbags' index."""

    topic: str
    msgtype: str


def message_class(msgtype: str) -> type:
    """rclpy message class of a rosbag type name such as ``sensor_msgs/msg/Image``."""
    try:
        package, kind, name = msgtype.split('/')
        return getattr(importlib.import_module(f'{package}.{kind}'), name)
    except (ValueError, ImportError, AttributeError) as err:
        raise PlayerError(f'message type {msgtype!r} is not available in this ROS '
                          'installation') from err


def _resolve_bag(path: str) -> Path:
    bag = Path(path)
    if (bag / 'bag' / 'metadata.yaml').exists():
        bag = bag / 'bag'
    if not (bag / 'metadata.yaml').exists():
        raise PlayerError(f'{path!r} is not a rosbag2 directory (no metadata.yaml)')
    return bag


class BagPlayer(Node):
    """Plays one bag (see the module docstring); :meth:`play` blocks until done."""

    def __init__(self, *, cli_args: list[str] | None = None, context=None) -> None:
        super().__init__('bag_player', cli_args=cli_args, context=context)

        def declare(name, default, description, lo=None, hi=None):
            extra = {}
            if lo is not None:
                extra['floating_point_range'] = [
                    FloatingPointRange(from_value=lo, to_value=hi, step=0.0)]
            try:
                return self.declare_parameter(
                    name, default, ParameterDescriptor(description=description, **extra)).value
            except Exception as err:  # rclpy raises several parameter exceptions
                raise PlayerError(f'parameter {name!r}: {err}') from err

        self.bag = _resolve_bag(str(declare('bag', '', 'rosbag2 directory to play')))
        self.rate = float(declare('rate', 1.0, 'playback speed factor', 0.01, 100.0))
        self.loop = bool(declare('loop', False, 'restart at the end'))
        self.exit_when_done = bool(declare('exit_when_done', True, 'exit after the last message'))
        self.publish_clock = bool(declare('publish_clock', True, 'publish /clock from bag time'))
        self.start_delay = float(declare('start_delay', 0.5, 'seconds before playing',
                                         0.0, 3600.0))
        self.wait_for_subscribers = bool(declare(
            'wait_for_subscribers', False, 'wait until every image topic has a subscriber'))
        self.clock_subscribers = int(declare(
            'clock_subscribers', 0, 'with wait_for_subscribers: matched /clock subscribers '
            'to wait for'))
        if self.clock_subscribers < 0:
            raise PlayerError(f'parameter clock_subscribers: must be >= 0, got '
                              f'{self.clock_subscribers}')
        self.subscriber_timeout = float(declare(
            'subscriber_timeout', 30.0, 'longest wait for subscribers, s', 0.0, 3600.0))
        topics = [t for t in declare('topics', [''], 'topics to play (default all)') if t]
        self.damaged: str | None = None  # why playing stopped before the end of the bag
        self._mcap_files: list[Path] = []
        try:
            self._reader = AnyReader([self.bag])
            self._reader.open()
            conns = self._reader.connections
        except Exception as err:  # rosbags raises several types for damaged bags
            self._reader = None
            self._mcap_files = sorted(self.bag.glob('*.mcap'))
            if not self._mcap_files:
                raise PlayerError(f'cannot open bag {self.bag}: {err}') from err
            # a truncated MCAP has no summary: play its complete records up to the damage
            self.get_logger().warning(f'bag {self.bag} is damaged ({err}); playing it up '
                                      'to the damage')
            found: dict[str, str] = {}
            try:
                for topic, msgtype, _, _ in stream_mcap(self._mcap_files):
                    found.setdefault(topic, msgtype)
            except BagError:
                pass
            conns = [_Connection(t, m) for t, m in found.items()]
        self._conns = [c for c in conns if not topics or c.topic in topics]
        if not self._conns:
            raise PlayerError(f'bag {self.bag} has none of the requested topics')
        # reliable publishers match both best-effort (sensor data) and reliable subscribers;
        # a reliable subscriber then gets every frame (bursts of large images overflow the
        # best-effort shared-memory path of Fast DDS)
        reliable = QoSProfile(depth=30, reliability=ReliabilityPolicy.RELIABLE)
        self._pubs = {}
        for c in self._conns:
            if c.topic not in self._pubs:
                self._pubs[c.topic] = self.create_publisher(message_class(c.msgtype),
                                                            c.topic, reliable)
        self._clock = self.create_publisher(Clock, '/clock', 10) if self.publish_clock else None
        self.published = 0
        self.burst_seconds: list[float] = []  # wall time to publish each stamp's messages
        self.loops = 0
        self.done = threading.Event()
        self._stop = threading.Event()

    def stop(self) -> None:
        self._stop.set()

    def _wait_subscribers(self) -> None:
        deadline = time.monotonic() + self.subscriber_timeout
        images = [p for c, p in self._pubs.items()
                  if any(x.topic == c and x.msgtype in IMAGE_TYPES for x in self._conns)]
        while time.monotonic() < deadline and not self._stop.is_set():
            clock_ok = self._clock is None or \
                self._clock.get_subscription_count() >= self.clock_subscribers
            if clock_ok and all(p.get_subscription_count() > 0 for p in images):
                return
            time.sleep(0.05)
        self.get_logger().warning('not every image topic has a subscriber (or /clock has '
                                  f'fewer than {self.clock_subscribers}); playing anyway')

    def play(self) -> None:
        """Publish every message at its (scaled) time; returns when done or stopped."""
        if self.wait_for_subscribers:
            self._wait_subscribers()
        if self._stop.wait(self.start_delay):
            return
        try:
            while not self._stop.is_set():
                if not self._play_once():
                    break
                self.loops += 1  # completed passes through the bag
                if not self.loop:
                    break
        finally:
            self.done.set()

    def _messages(self):
        """(topic, log time ns, cdr) of the played topics; a damaged part ends the pass
        (``damaged`` says why) after every message before it."""
        topics = {c.topic for c in self._conns}
        if self._reader is not None:
            source = ((c.topic, stamp, raw)
                      for c, stamp, raw in self._reader.messages(connections=self._conns))
        else:
            source = ((topic, stamp, raw)
                      for topic, _, stamp, raw in stream_mcap(self._mcap_files, topics))
        played = 0
        try:
            for item in source:
                played += 1
                yield item
        except Exception as err:  # damaged chunk, truncated file ...
            self.damaged = f'{type(err).__name__}: {str(err)[:200]}'
            self.get_logger().error(f'bag {self.bag} is damaged after {self.published} '
                                    f'messages: {self.damaged}')
            return
        declared = sum(getattr(c, 'msgcount', 0) for c in self._conns)
        if self._reader is not None and played < declared:  # a chunk the reader skipped
            self.damaged = f'{declared - played} of its {declared} messages unreadable'
            self.get_logger().error(f'bag {self.bag} is damaged: {self.damaged}')

    def _play_once(self) -> bool:
        """One pass through the bag; False when stopped before the end."""
        wall0 = bag0 = None
        clock = Clock()
        last = None  # bag time of the previous message
        burst0 = 0.0
        for topic, stamp, raw in self._messages():
            if self._stop.is_set():
                return False
            if wall0 is None:
                wall0, bag0 = time.monotonic(), stamp
            if stamp != last:  # the bag time advances: wait for it, then tick /clock once
                if last is not None:
                    self.burst_seconds.append(time.monotonic() - burst0)
                delay = wall0 + (stamp - bag0) / 1e9 / self.rate - time.monotonic()
                if delay > 0 and self._stop.wait(delay):
                    return False
                burst0 = time.monotonic()
                if self._clock is not None:
                    ns_to_stamp(stamp, clock.clock)
                    self._clock.publish(clock)
                last = stamp
            self._pubs[topic].publish(raw if isinstance(raw, bytes) else bytes(raw))
            self.published += 1
        if last is not None:
            self.burst_seconds.append(time.monotonic() - burst0)
        return self.damaged is None or not self.loop

    def destroy_node(self) -> None:
        self._stop.set()
        if self._reader is not None:
            self._reader.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """Entry point ``bag_player``; exits non-zero when the bag cannot be played."""
    use_large_shm_segment()  # before rclpy.init: bursts of images fit in shared memory
    rclpy.init(args=args)
    node = None
    code = 0
    try:
        node = BagPlayer()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        player = threading.Thread(target=node.play, daemon=True)
        player.start()
        while rclpy.ok() and not (node.done.is_set() and node.exit_when_done):
            executor.spin_once(timeout_sec=0.1)
        bursts = sorted(node.burst_seconds) or [0.0]
        node.get_logger().info(
            f'published {node.published} messages from {node.bag}; one stamp\'s messages '
            f'took p50 {1e3 * bursts[len(bursts) // 2]:.1f} ms, '
            f'p95 {1e3 * bursts[min(len(bursts) - 1, int(0.95 * len(bursts)))]:.1f} ms')
        if node.damaged is not None:
            print(f'bag_player: error: {node.bag} is damaged; played {node.published} '
                  f'messages up to the damage ({node.damaged})', file=sys.stderr)
            code = 1
    except PlayerError as err:
        print(f'bag_player: error: {err}', file=sys.stderr)
        code = 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return code


if __name__ == '__main__':
    sys.exit(main())
