"""``mbtrack`` with rclpy hidden, so that ``replay`` writes no tracks.mcap (its writer child
needs rclpy): the replay's speed without the writer (docs/live_measurements.md, "Offline and
live check on the tenth-session tree").

Usage: python docs/diag/replay_no_writer.py replay REC --out O --seed 0 --params P
"""
import sys

sys.modules['rclpy'] = None  # importlib.util.find_spec('rclpy') is then None
from mbtrack_ros.cli import main  # noqa: E402

sys.exit(main())
