"""Compare a tracks CSV with the Pose2Sim reference of the real clip; plot the error curve.

Usage: python docs/real_data/compare_reference.py TRACKS.csv GROUND_TRUTH.csv OUT.png [TITLE]

For every reference frame, the track nearest to the reference hip midpoint (floor, metres) is
taken as the subject's track. Prints: first frame with a track within 0.5 m, the ids assigned
to the subject over time (switches), the fraction of tracked frames within 0.20 / 0.15 m,
median and 90th-percentile error, and the tracks never near the subject (others).
"""
from __future__ import annotations

import sys
from collections import defaultdict

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from mbtrack_ros.recording.csvfiles import read_ground_truth, read_tracks  # noqa: E402


def main(tracks_csv: str, truth_csv: str, out_png: str, title: str = '') -> None:
    truth = {r.frame: r for r in read_ground_truth(truth_csv) if r.person_id == 1}
    by_frame = defaultdict(list)
    for t in read_tracks(tracks_csv):
        by_frame[t.frame].append(t)
    frames = sorted(truth)
    err = np.full(len(frames), np.nan)
    ids = np.full(len(frames), -1)
    for i, f in enumerate(frames):
        ref = np.array([truth[f].x, truth[f].y])
        cands = by_frame.get(f, [])
        if cands:
            d = [np.hypot(t.x - ref[0], t.y - ref[1]) for t in cands]
            j = int(np.argmin(d))
            if d[j] < 0.5:
                err[i], ids[i] = d[j], cands[j].track_id
    tracked = np.isfinite(err)
    first = frames[int(np.argmax(tracked))] if tracked.any() else None
    runs = [int(ids[0])] if len(ids) else []
    for v in ids[1:]:
        if int(v) != runs[-1]:
            runs.append(int(v))
    subject_ids = {int(v) for v in ids if v >= 0}
    others = sorted({t.track_id for ts in by_frame.values() for t in ts} - subject_ids)
    e = err[tracked]
    print(f'frames {len(frames)}, tracked {int(tracked.sum())}, first tracked frame {first}')
    print(f'subject id sequence over time (-1 = no track within 0.5 m): {runs}')
    if e.size:
        print(f'within 0.20 m: {np.mean(e <= 0.20):.1%}, within 0.15 m: {np.mean(e <= 0.15):.1%}, '
              f'median {np.median(e) * 100:.1f} cm, p90 {np.percentile(e, 90) * 100:.1f} cm, '
              f'max {e.max() * 100:.1f} cm')
    for tid in others:
        rows = [t for ts in by_frame.values() for t in ts if t.track_id == tid]
        xy = np.array([[t.x, t.y] for t in rows])
        print(f'other track {tid}: {len(rows)} frames, frames {min(t.frame for t in rows)}-'
              f'{max(t.frame for t in rows)}, mean position ({xy[:, 0].mean():.2f}, '
              f'{xy[:, 1].mean():.2f}) m')
    fig, ax = plt.subplots(figsize=(7, 3.2), dpi=110)
    ax.plot(frames, err * 100, '.-', lw=1, ms=3, label='nearest track')
    ax.axhline(20, color='r', ls='--', lw=0.8, label='20 cm')
    ax.axhline(15, color='orange', ls=':', lw=0.8, label='15 cm')
    ax.set_xlabel('frame (60 fps)')
    ax.set_ylabel('floor error vs reference hip (cm)')
    ax.set_title(title or tracks_csv, fontsize=9)
    ax.set_ylim(0, max(30, np.nanmax(err) * 100 * 1.1 if tracked.any() else 30))
    ax.legend(fontsize=8, loc='upper right')
    fig.tight_layout()
    fig.savefig(out_png)


if __name__ == '__main__':
    main(*sys.argv[1:])
