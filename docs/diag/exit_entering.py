"""Identity switches after an exit release: was the person coming in? (eleventh session)

Usage: exit_entering.py OUT REC [OUT REC ...]

For each switch that ``detection_eval.py classes`` calls "a released (exit)": the person's
place and their first and last ground-truth frames, and the released track's birth frame
and place, how far into the room it ever came (smallest y; the clear-room door is on the
y = 4.7 m side) and its age. A track born in the doorway of a person whose first frame is
a few seconds before is the track of someone coming in (docs/detection.md, "Fresh
recordings, the suite and the exclusion radius").
"""
import csv

from _eval import detection_eval as de, pairs

for out, rec in pairs('exit_entering.py OUT REC [OUT REC ...]'):
    tracks: dict[int, list] = {}
    for r in csv.DictReader(open(out / 'tracks.csv', encoding='utf-8')):
        tracks.setdefault(int(r['track_id']), []).append(
            (int(r['frame']), float(r['x']), float(r['y'])))
    people: dict[int, list] = {}
    for r in csv.DictReader(open(rec / 'ground_truth.csv', encoding='utf-8')):
        people.setdefault(int(r['person_id']), []).append(
            (int(r['frame']), float(r['x']), float(r['y'])))
    for s in de.switch_classes(out, rec):
        if s['kind'] != 'a released (exit)':
            continue
        t, p = tracks[s['old']], people[s['person']]
        here = next(q for q in p if q[0] == s['frame'])
        print(f"{out.name} person {s['person']} frame {s['frame']}: person at y {here[2]:.2f}, "
              f"ground truth frames {p[0][0]}-{p[-1][0]} | track {s['old']} born at frame "
              f"{t[0][0]} at ({t[0][1]:.2f}, {t[0][2]:.2f}), smallest y "
              f"{min(q[2] for q in t):.2f}, last ({t[-1][1]:.2f}, {t[-1][2]:.2f}), "
              f"age {(t[-1][0] - t[0][0]) / de.FPS:.1f} s")
