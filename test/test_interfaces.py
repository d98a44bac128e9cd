"""The interface packages of interfaces/ have the released Jazzy packages' type hashes, and
the bootstrap's build step skips, or says what is off, without building."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from mbtrack_ros import interfaces_build

INTERFACES = Path(__file__).resolve().parents[1] / 'interfaces'

# RIHS01 type hashes of the released ROS 2 Jazzy packages. vision_msgs 4.1.1 and tf2_msgs
# 0.36: as compiled into code generated against the released packages (the
# ``*__description.c`` files rosidl_generator_c writes: the hash of Detection3DArray, and
# the EXPECTED_HASH of the TFMessage a message of another package holds). hri_msgs 2:
# IdsList has had the fields ``std_msgs/Header header``, ``string[] ids`` since its port to
# ROS 2 (hri_msgs 2.0.0); its hash is the one rosbags computes from those fields.
RELEASED = {
    'vision_msgs/msg/Detection3DArray':
        'RIHS01_793f5eab9595ac1c0da07873cc859db42eae51f0ee76056db8562515d830e018',
    'vision_msgs/msg/Detection3D':
        'RIHS01_ddd703be132ab0b69d33121f1bb034132bfbb3b0ac5f9fb1516005ba1c8a265b',
    'vision_msgs/msg/BoundingBox3D':
        'RIHS01_bbb73a65c163d7f9bb29009c7bde9f7faa576bd2d23299c4511d19230dab4698',
    'vision_msgs/msg/ObjectHypothesis':
        'RIHS01_51da43cec11c01957a64d1e05a24acd18aae7745ec30b74348ad5f6d634f7f90',
    'vision_msgs/msg/ObjectHypothesisWithPose':
        'RIHS01_41c12344c0396c48b81df12467c192d99b2a0eb1463c5c37194e4223251c80bc',
    'tf2_msgs/msg/TFMessage':
        'RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087',
    'hri_msgs/msg/IdsList':
        'RIHS01_7e0812d1ac945c98fd3e393568d581ad0ab567f37b24eff633eab778c1bfe62d',
}


def test_definitions_hash_as_released_with_rosbags():
    """rosbags' own RIHS01 implementation, on the .msg files of interfaces/."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    types = {}
    for name in RELEASED:
        package, _, message = name.split('/')
        text = (INTERFACES / package / 'msg' / f'{message}.msg').read_text()
        if name not in store.fielddefs:
            types.update(get_types_from_msg(text, name))
    store.register(types)
    assert {name: store.hash_rihs01(name) for name in RELEASED} == RELEASED


@pytest.mark.parametrize('name', sorted(RELEASED))
def test_installed_packages_hash_as_released(name):
    """The type descriptions rosidl wrote for the installed packages (the bootstrap's
    build, or a ROS 2 installation's released packages)."""
    package, _, message = name.split('/')
    pytest.importorskip(f'{package}.msg', reason=f'{package} is not built here')

    candidates = [Path(sys.prefix) / 'share' / package / 'msg' / f'{message}.json']
    try:
        from ament_index_python.packages import get_package_share_directory
        candidates.insert(0, Path(get_package_share_directory(package)) / 'msg'
                          / f'{message}.json')
    except (LookupError, OSError, ValueError):
        pass
    path = next(p for p in candidates if p.is_file())
    hashes = {h['type_name']: h['hash_string'] for h in json.loads(path.read_text())[
        'type_hashes']}
    assert hashes[name] == RELEASED[name]


def test_digest_follows_the_definitions(tmp_path):
    (tmp_path / 'a' / 'msg').mkdir(parents=True)
    (tmp_path / 'a' / 'msg' / 'X.msg').write_text('int32 x\n')
    first = interfaces_build.definitions_digest(tmp_path)
    assert interfaces_build.definitions_digest(tmp_path) == first
    (tmp_path / 'a' / 'msg' / 'X.msg').write_text('int64 x\n')
    assert interfaces_build.definitions_digest(tmp_path) != first
    assert interfaces_build.definitions_digest() != first


def test_up_to_date_stamp_skips_everything(tmp_path, monkeypatch, capsys):
    """A stamp with the current digest: no subprocess at all, nothing printed."""
    (tmp_path / interfaces_build.STAMP_NAME).write_text(json.dumps(
        {'digest': interfaces_build.definitions_digest(), 'built': list(
            interfaces_build.PACKAGES), 'unavailable': []}))

    def refuse(*args, **kwargs):
        raise AssertionError('no subprocess when the stamp is up to date')

    monkeypatch.setattr(interfaces_build.subprocess, 'run', refuse)
    assert interfaces_build.ensure_interfaces(Path(sys.executable), tmp_path) == []
    assert capsys.readouterr().err == ''


def test_without_build_tools_one_line_says_what_is_off(tmp_path, monkeypatch, capsys):
    """Definitions changed since the last build and no cmake/compiler: one line naming the
    outputs that are off, the packages returned, nothing raised."""
    (tmp_path / interfaces_build.STAMP_NAME).write_text(json.dumps(
        {'digest': 'older', 'built': list(interfaces_build.PACKAGES), 'unavailable': []}))
    monkeypatch.setattr(interfaces_build.shutil, 'which', lambda name: None)
    off = interfaces_build.ensure_interfaces(Path(sys.executable), tmp_path)
    assert off == list(interfaces_build.PACKAGES)
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1
    assert 'no cmake' in lines[0] and 'REP-155' in lines[0] and '/tf' in lines[0]


def test_interfaces_are_ignored_by_colcon_and_list_their_messages():
    """colcon skips interfaces/ (a ROS workspace uses the released packages), and each
    CMakeLists names every .msg file of its package."""
    assert (INTERFACES / 'COLCON_IGNORE').is_file()
    for package in interfaces_build.PACKAGES:
        cmake = (INTERFACES / package / 'CMakeLists.txt').read_text()
        msgs = sorted(p.name for p in (INTERFACES / package / 'msg').glob('*.msg'))
        assert msgs and all(f'msg/{m}' in cmake for m in msgs)
        assert f'<name>{package}</name>' in (INTERFACES / package / 'package.xml').read_text()
