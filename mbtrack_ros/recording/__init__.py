"""Recordings: rosbag2 (MCAP/sqlite3) reading and writing, CSV track and ground-truth files."""
