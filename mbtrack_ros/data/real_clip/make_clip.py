"""Regenerate this directory from the Pose2Sim demo data (see README.md here).

Usage: python make_clip.py /path/to/pose2sim_lab4cam
"""
from __future__ import annotations

import shutil
import sys
from pathlib import Path

import cv2
import yaml

FIRST, COUNT = 45, 10          # frames 45..54 of the 100-frame clip (frame 50 inside)
START_COUNT = 18               # videos_start/: frames 0..17 (automatic detection from the start)
START_QUALITY = 70             # MJPG quality of videos_start/ (keeps it under 2 MB)
SIZE = (272, 480)              # 1/4 of the calibrated 1088 x 1920
QUALITY = 80                   # MJPG quality


def main(src: Path) -> None:
    here = Path(__file__).resolve().parent
    for name in ('LICENSE', 'Calib.qca.txt', 'calibration_opencv.json'):
        shutil.copy(src / name, here / name)
    # multi_P1_0-100.trc is not copied: it belongs to another Pose2Sim trial and does not
    # project onto anyone in these videos with this calibration (see README.md)
    shutil.copy(src / 'reference_pose2sim_output' / 'single_0-100.trc', here)
    calib = yaml.safe_load((src / 'calibration_opencv.json').read_text())
    (here / 'camera_info').mkdir(exist_ok=True)
    for cam, entry in calib.items():  # intrinsics only, camera_calibration_parsers layout
        w, h = entry['image_size']
        k = [v for row in entry['K'] for v in row]
        doc = {'image_width': w, 'image_height': h, 'camera_name': cam,
               'camera_matrix': {'rows': 3, 'cols': 3, 'data': k},
               'distortion_model': 'plumb_bob',
               'distortion_coefficients': {'rows': 1, 'cols': 5,
                                           'data': list(entry['dist']) + [0.0]},
               'rectification_matrix': {'rows': 3, 'cols': 3,
                                        'data': [1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0]},
               'projection_matrix': {'rows': 3, 'cols': 4,
                                     'data': k[:3] + [0.0] + k[3:6] + [0.0] + k[6:] + [0.0]}}
        (here / 'camera_info' / f'{cam}.yaml').write_text(yaml.safe_dump(doc, sort_keys=False))
    for folder, first, count, quality in (('videos', FIRST, COUNT, QUALITY),
                                          ('videos_start', 0, START_COUNT, START_QUALITY)):
        (here / folder).mkdir(exist_ok=True)
        for video in sorted((src / 'single_person' / 'videos').glob('cam*.mp4')):
            cap = cv2.VideoCapture(str(video))
            cap.set(cv2.CAP_PROP_POS_FRAMES, first)
            out = cv2.VideoWriter(str(here / folder / f'{video.stem}.avi'),
                                  cv2.VideoWriter_fourcc(*'MJPG'), 60.0, SIZE)
            out.set(cv2.VIDEOWRITER_PROP_QUALITY, quality)
            for _ in range(count):
                ok, frame = cap.read()
                assert ok, video
                out.write(cv2.resize(frame, SIZE, interpolation=cv2.INTER_AREA))
            out.release()
            cap.release()

if __name__ == '__main__':
    main(Path(sys.argv[1]))
