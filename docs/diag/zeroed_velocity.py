"""Where a variant gave a detection no velocity that main gave one: main's velocity and
zero against the person's (the nearest ground-truth row within 0.5 m, over the six frames
around the decision), for each decision row both runs hold (same frame and floor point;
docs/detection.md, "No velocity from a detection that strayed: tried, not kept").

usage: .venv/bin/python docs/diag/zeroed_velocity.py MAIN VARIANT REC [MAIN VARIANT REC ...]
    MAIN, VARIANT: ``detection_eval.py run`` outputs of one recording and seed.
"""
import json
import sys
from pathlib import Path

import numpy as np

from _eval import person_velocity, run_context

args = [Path(a) for a in sys.argv[1:]]
if not args or len(args) % 3:
    sys.exit(__doc__.split('usage: ')[1])
errors = []
for main, variant, rec in zip(args[::3], args[1::3], args[2::3]):
    events, _, _, people, _ = run_context(main, rec)
    theirs = {(e['frame'], tuple(e['xy'])): e['v']
              for e in json.loads((variant / 'events.json').read_text(encoding='utf-8'))
              if e['kind'] == 'decision' and 'v' in e}
    for e in events:
        if e['kind'] != 'decision' or 'v' not in e or not any(e['v']):
            continue
        other = theirs.get((e['frame'], tuple(e['xy'])))
        if other is None or any(other):
            continue
        walk = person_velocity(people, e['frame'], e['xy'])
        if walk is None:
            print(f"{main.name} frame {e['frame']}: {e['action']}, given {e['v']}; "
                  'nobody within 0.5 m')
            continue
        given, walk = np.asarray(e['v']), np.asarray(walk)
        errors.append((np.hypot(*(given - walk)), np.hypot(*walk)))
        print(f"{main.name} frame {e['frame']}: {e['action']}, given ({given[0]:.2f}, "
              f"{given[1]:.2f}), person ({walk[0]:.2f}, {walk[1]:.2f}) m/s: error "
              f'{errors[-1][0]:.2f} as given, {errors[-1][1]:.2f} with none')
if errors:
    mean = np.mean(errors, axis=0)
    print(f'{len(errors)} decisions: mean error {mean[0]:.3f} m/s as given, {mean[1]:.3f} '
          'with none')
