"""How well the tracks' velocities follow walking people (fifteenth session).

Usage: walking_velocity.py REC SEED FIRST LAST [TRACKER_CONFIG_JSON]

Steps the tracker as ``detection_eval.py run`` does (same config and seed; the JSON, e.g.
'{"motion": {"orientation_follows_velocity": true}}', goes on top) up to frame LAST. Every
frame from FIRST, each track within 0.3 m of a ground-truth person walking faster than
0.4 m/s (over the last 3 frames) gives a row: the person's velocity, the track's weighted
mean velocity and mean orientation. Prints the correlation of the velocity components, how
often their signs agree, the median speeds, the median projection of the track's velocity
on the person's walking direction, the median angle between the track's orientation and
the walking direction, and that of the direction of the track's velocity where it is at
least 0.2 m/s (the yaw of ``~/people``). For the tracks on people standing still (slower
than 0.1 m/s): the quartiles of the mean velocity's speed and of the particles' rms speed.
"""
import csv
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _eval import tracked_frames, weighted_cloud  # noqa: E402

from mbtrack_ros.core.state import THETA, VX, VY, X, Y  # noqa: E402

rec, seed, first, last = Path(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
config = json.loads(sys.argv[5]) if len(sys.argv) > 5 else {}
gt: dict[int, dict[int, tuple[float, float]]] = {}
for r in csv.DictReader(open(rec / 'ground_truth.csv')):
    gt.setdefault(int(r['frame']), {})[int(r['person_id'])] = (float(r['x']), float(r['y']))
rows, still = [], []
for fs, _, tracker in tracked_frames(rec, seed, last, **config):
    f = fs.index
    if f < first or f not in gt or f - 3 not in gt:
        continue
    for tid in tracker.filter.track_ids():
        p, w, _ = weighted_cloud(tracker, tid)
        m = w @ p
        theta = np.arctan2(w @ np.sin(p[:, THETA]), w @ np.cos(p[:, THETA]))
        pid, (gx, gy) = min(gt[f].items(),
                            key=lambda kv: np.hypot(kv[1][0] - m[X], kv[1][1] - m[Y]))
        if np.hypot(gx - m[X], gy - m[Y]) > 0.3 or pid not in gt[f - 3]:
            continue
        ox, oy = gt[f - 3][pid]
        vx, vy = (gx - ox) * 5, (gy - oy) * 5            # 3 frames at 15 fps
        if np.hypot(vx, vy) >= 0.4:
            rows.append((vx, vy, m[VX], m[VY], np.arctan2(vy, vx), theta))
        elif np.hypot(vx, vy) < 0.1:
            still.append((np.hypot(m[VX], m[VY]), np.sqrt(w @ (p[:, VX] ** 2 + p[:, VY] ** 2))))
r = np.array(rows)
speed = np.hypot(r[:, 0], r[:, 1])
print(f'{len(r)} track frames on a walking person')
print(f'correlation vx {np.corrcoef(r[:, 0], r[:, 2])[0, 1]:.2f}, '
      f'vy {np.corrcoef(r[:, 1], r[:, 3])[0, 1]:.2f}; signs agree vx '
      f'{np.mean(np.sign(r[:, 0]) == np.sign(r[:, 2])):.2f}, '
      f'vy {np.mean(np.sign(r[:, 1]) == np.sign(r[:, 3])):.2f}')
print(f'median speed: person {np.median(speed):.2f} m/s, track '
      f'{np.median(np.hypot(r[:, 2], r[:, 3])):.2f} m/s; median projection of the track '
      f'velocity on the walking direction '
      f'{np.median((r[:, 0] * r[:, 2] + r[:, 1] * r[:, 3]) / speed):.2f} m/s')
print(f'median |orientation - walking direction| '
      f'{np.median(np.abs(np.angle(np.exp(1j * (r[:, 5] - r[:, 4]))))):.2f} rad')
heading = np.arctan2(r[:, 3], r[:, 2])
moving = np.hypot(r[:, 2], r[:, 3]) >= 0.2          # the ~/people yaw: velocity direction
print(f'median |velocity direction - walking direction| where the track moves >= 0.2 m/s '
      f'({moving.mean():.0%} of the frames): '
      f'{np.median(np.abs(np.angle(np.exp(1j * (heading - r[:, 4]))))[moving]):.2f} rad')
s = np.array(still)
print(f'{len(s)} track frames on a person standing still: mean-velocity speed quartiles '
      f'{np.round(np.percentile(s[:, 0], [25, 50, 75]), 2)} m/s, particle rms speed '
      f'quartiles {np.round(np.percentile(s[:, 1], [25, 50, 75]), 2)} m/s')
