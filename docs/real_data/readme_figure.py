"""The README picture of the real clip: tracked shapes and ids, and the debug occlusion images.

Usage: python docs/real_data/readme_figure.py RECORDING OUT.png [--frame F] [--seed S]

Runs the tracker with automatic detection (what ``mbtrack replay`` does without
``--init-from``) over RECORDING up to frame F, then draws one figure:

* top row, every camera: the image with each reported track's rendered body silhouette
  (head, torso, legs of the shape model, 003 §2.1) outlined in the track's colour and its id
  at the head;
* bottom row, every camera: the node's ``~/debug/<camera>/occlusion`` image of that frame
  (the same ``occlusion_layers`` + ``debug_overlay`` code): silhouettes tinted per track and,
  in red, the probability that a silhouette pixel is hidden by another person (000 Eq. 34).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np

from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.core.tracker import Tracker, TrackerConfig
from mbtrack_ros.nodes.debug import occlusion_layers
from mbtrack_ros.nodes.messages import debug_overlay, track_color
from mbtrack_ros.recording.bag import RecordingReader


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('recording')
    parser.add_argument('out')
    parser.add_argument('--frame', type=int, default=90)
    parser.add_argument('--seed', type=int, default=0)
    args = parser.parse_args()
    room = RoomCalibration.load(Path(args.recording) / 'calibration.yaml')
    tracker = Tracker(room, TrackerConfig(detection=True, seed=args.seed),
                      rng=np.random.default_rng(args.seed))
    with RecordingReader(args.recording) as reader:
        for fs in reader.frames():
            result = tracker.step(fs.stamp_ns, fs.images)
            if fs.index == args.frame:
                break
        else:
            raise SystemExit(f'readme_figure: the recording has no frame {args.frame}')
    models = tracker.models  # track id -> PersonModel of the live tracks
    top, bottom = [], []
    for name in room.names:
        camera = room.cameras[name]
        image = fs.images[name]
        occlusion, silhouettes = occlusion_layers(tracker.measurement, camera, result, models)
        outlined = image.copy()
        for track_id, mask in silhouettes.items():
            colour = tuple(int(255 * c) for c in track_color(track_id)[:3])
            contours, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL,
                                           cv2.CHAIN_APPROX_SIMPLE)
            cv2.drawContours(outlined, contours, -1, colour, 2)
            ys, xs = np.nonzero(mask)
            if ys.size:
                top_y = int(ys.min())
                x = int(np.median(xs[ys < top_y + 5]))
                cv2.putText(outlined, str(track_id), (max(x - 6, 0), max(top_y - 6, 12)),
                            cv2.FONT_HERSHEY_SIMPLEX, 0.7, colour, 2)
        cv2.putText(outlined, f'{name} frame {fs.index}', (4, 16), cv2.FONT_HERSHEY_SIMPLEX,
                    0.45, (255, 255, 0), 1)
        top.append(outlined)
        bottom.append(debug_overlay(image, occlusion=occlusion, silhouettes=silhouettes))
    figure = np.vstack([np.hstack(top), np.hstack(bottom)])
    cv2.imwrite(args.out, cv2.cvtColor(figure, cv2.COLOR_RGB2BGR))
    print(f'{args.out}: frame {fs.index}, tracks '
          f'{[(t.track_id, round(float(t.mean[0]), 2), round(float(t.mean[1]), 2)) for t in result.tracks]}')


if __name__ == '__main__':
    main()
