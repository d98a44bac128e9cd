"""DDS transport settings for streams of large images (Fast DDS shared memory).

Fast DDS (the default RMW of Jazzy) gives every participant a 512 kB shared-memory segment
for the payloads it writes. One 320x240 rgb8 image is 230 kB, so a frame set of four images
published back to back does not fit: the samples that find no room are repaired later by the
reliability protocol, and the last image of a set arrives hundreds of milliseconds late.
With a 16 MB segment the same stream arrives within a few milliseconds. :func:`use_large_shm_segment` installs such a profile for this process
(shared memory plus UDPv4, as the built-in transports, only the segment larger) unless the
user configured Fast DDS already. It must run before ``rclpy.init``.

The profile file is created safely: in a new private directory (``tempfile.mkdtemp``, mode
0700) with ``O_CREAT | O_EXCL | O_NOFOLLOW`` (mode 0600), so no other user's file or planted
symbolic link is ever read or written; it is removed when the process exits. Other processes
that publish large images (camera drivers) need the same setting: write
:func:`fastdds_profile` to a file of their own and export ``FASTRTPS_DEFAULT_PROFILES_FILE``.
"""
from __future__ import annotations

import atexit
import os
import shutil
import stat
import tempfile
from pathlib import Path

__all__ = ['SEGMENT_BYTES', 'fastdds_profile', 'use_large_shm_segment']

SEGMENT_BYTES = 16 * 1024 * 1024  # shared-memory segment per participant, bytes
_PROFILE_VARS = ('FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_DEFAULT_PROFILES_FILE',
                 'FASTDDS_BUILTIN_TRANSPORTS')


def fastdds_profile(segment_bytes: int = SEGMENT_BYTES) -> str:
    """Fast DDS XML: default participant with SHM (``segment_bytes``) and UDPv4 transports."""
    return f'''<?xml version="1.0" encoding="UTF-8" ?>
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <transport_descriptors>
    <transport_descriptor>
      <transport_id>mbtrack_shm</transport_id>
      <type>SHM</type>
      <segment_size>{int(segment_bytes)}</segment_size>
    </transport_descriptor>
    <transport_descriptor>
      <transport_id>mbtrack_udp</transport_id>
      <type>UDPv4</type>
    </transport_descriptor>
  </transport_descriptors>
  <participant profile_name="mbtrack_large_images" is_default_profile="true">
    <rtps>
      <userTransports>
        <transport_id>mbtrack_shm</transport_id>
        <transport_id>mbtrack_udp</transport_id>
      </userTransports>
      <useBuiltinTransports>false</useBuiltinTransports>
    </rtps>
  </participant>
</profiles>
'''


_written: Path | None = None  # the profile this process created


def _ours(path: Path) -> bool:
    """True for a regular file (not a link) owned by this user in a directory only this user
    may enter: the file :func:`_write_profile` created and nobody replaced."""
    try:
        info, parent = path.lstat(), path.parent.lstat()
    except OSError:
        return False
    return (stat.S_ISREG(info.st_mode) and info.st_uid == os.getuid()
            and stat.S_ISDIR(parent.st_mode) and parent.st_uid == os.getuid()
            and stat.S_IMODE(parent.st_mode) & 0o077 == 0)


def _write_profile(text: str) -> Path:
    """Write ``text`` to a new file in a new private temporary directory; removed at exit."""
    directory = Path(tempfile.mkdtemp(prefix='mbtrack_fastdds_'))  # new, unique, 0700
    path = directory / 'profile.xml'
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, 'O_NOFOLLOW', 0)
    try:
        fd = os.open(path, flags, 0o600)
        with os.fdopen(fd, 'w', encoding='utf-8') as handle:
            handle.write(text)
    except OSError:
        shutil.rmtree(directory, ignore_errors=True)
        raise
    atexit.register(shutil.rmtree, directory, ignore_errors=True)
    return path


def use_large_shm_segment(environ: dict | None = None) -> Path | None:
    """Point Fast DDS at :func:`fastdds_profile` in ``environ`` (default ``os.environ``).

    Does nothing (returns None) when another RMW is selected or the user already set a
    Fast DDS profile or transport variable; otherwise writes the profile (once per process,
    in a private directory: module docstring) and returns its path.
    """
    global _written
    env = os.environ if environ is None else environ
    rmw = env.get('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp')
    if not rmw.startswith('rmw_fastrtps') or any(env.get(v) for v in _PROFILE_VARS):
        return None
    text = fastdds_profile()
    try:
        if _written is None or not _ours(_written) \
                or Path(tempfile.gettempdir()) not in _written.parents:
            _written = _write_profile(text)
    except OSError:
        return None  # keep the Fast DDS defaults rather than fail to start
    env['FASTRTPS_DEFAULT_PROFILES_FILE'] = str(_written)
    return _written
