"""DDS transport settings for streams of large images (Fast DDS shared memory).

Fast DDS (the default RMW of Jazzy) gives every participant a 512 kB shared-memory segment
for the payloads it writes. One 320x240 rgb8 image is 230 kB, so a frame set of four images
published back to back does not fit: the samples that find no room are repaired later by the
reliability protocol, and the last image of a set arrives hundreds of milliseconds late.
With a 16 MB segment the same stream arrives within a few milliseconds. :func:`use_large_shm_segment` installs such a profile for this process
(shared memory plus UDPv4, as the built-in transports, only the segment larger) unless the
user configured Fast DDS already. It must run before ``rclpy.init``.

Other processes that publish large images (camera drivers) need the same setting: export
``FASTRTPS_DEFAULT_PROFILES_FILE`` pointing to the file this writes (path returned).
"""
from __future__ import annotations

import os
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


def use_large_shm_segment(environ: dict | None = None) -> Path | None:
    """Point Fast DDS at :func:`fastdds_profile` in ``environ`` (default ``os.environ``).

    Does nothing (returns None) when another RMW is selected or the user already set a
    Fast DDS profile or transport variable; otherwise writes the profile once per user to
    the temporary directory and returns its path.
    """
    env = os.environ if environ is None else environ
    rmw = env.get('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp')
    if not rmw.startswith('rmw_fastrtps') or any(env.get(v) for v in _PROFILE_VARS):
        return None
    path = Path(tempfile.gettempdir()) / f'mbtrack_fastdds_{os.getuid()}.xml'
    text = fastdds_profile()
    try:
        if not path.exists() or path.read_text() != text:
            tmp = path.with_suffix(f'.{os.getpid()}.tmp')
            tmp.write_text(text)
            tmp.replace(path)  # atomic: concurrent nodes never read half a file
    except OSError:
        return None  # keep the Fast DDS defaults rather than fail to start
    env['FASTRTPS_DEFAULT_PROFILES_FILE'] = str(path)
    return path
