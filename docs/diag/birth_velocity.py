"""The velocity a confirmed detection gave the track it started or moved (``v`` of the
birth, move and reuse rows in events.json) against its person's (nearest ground-truth row
within 0.5 m; velocity over the six frames around the decision), and the error had the
given velocity been scaled by each factor (docs/detection.md, "A shrunk detection
velocity"; the factors are relative to the velocity of the run read, ``velocity_shrink``
already applied).

usage: .venv/bin/python docs/diag/birth_velocity.py OUT REC [OUT REC ...]
"""
import numpy as np

from _eval import pairs, person_velocity, run_context

FACTORS = (0.0, 0.25, 0.5, 0.6, 0.65, 0.7, 0.75, 0.8, 0.85, 0.9, 1.0, 1.25)
HALF = 3                                 # frames either side of the decision

given, truth = [], []
for out, rec in pairs('birth_velocity.py OUT REC [OUT REC ...]'):
    events, _, _, people, _ = run_context(out, rec)
    for e in events:
        if e['kind'] != 'decision' or 'v' not in e \
                or not e['action'].startswith(('birth', 'move', 'reuse')):
            continue
        walk = person_velocity(people, e['frame'], e['xy'], half=HALF)
        if walk is not None:
            given.append(e['v'])
            truth.append(walk)
if not given:
    raise SystemExit('no birth, move or reuse row with a velocity near a person')
given, truth = np.asarray(given), np.asarray(truth)
speed = np.hypot(*given.T)
print(f'{len(given)} decisions; given speed median {np.median(speed):.2f} m/s (zero on '
      f'{int((speed == 0).sum())}), person median {np.median(np.hypot(*truth.T)):.2f} m/s')
print('| factor | mean error (m/s) | median | 90th percentile |')
print('| --- | --- | --- | --- |')
for k in FACTORS:
    err = np.hypot(*(k * given - truth).T)
    print(f'| {k:g} | {err.mean():.3f} | {np.median(err):.3f} | {np.quantile(err, 0.9):.3f} |')
