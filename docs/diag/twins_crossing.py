"""How often HJS and the separable filter keep the twins of test_filters' crossing clip.

Usage: twins_crossing.py [SEEDS]   (default 80, the test's count)

Runs ``_crossing_run`` of test/test_filters.py for both filters on seeds 0..SEEDS-1 and
prints how many runs each got right, how many only one of them did, and in how many the
far person's track was hidden (less than half visible) for 3 frames or more.
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / 'test'))
from test_filters import _crossing_run  # noqa: E402

seeds = range(int(sys.argv[1]) if len(sys.argv) > 1 else 80)
hjs = [_crossing_run('hjs', s) for s in seeds]
sep = [_crossing_run('separable', s)[0] for s in seeds]
print(f'{len(seeds)} seeds: HJS right {sum(ok for ok, _ in hjs)}, separable right {sum(sep)}, '
      f'only HJS {sum(ok and not o for (ok, _), o in zip(hjs, sep))}, only separable '
      f'{sum(o and not ok for (ok, _), o in zip(hjs, sep))}; far person hidden >= 3 frames in '
      f'{sum(h >= 3 for _, h in hjs)} HJS runs')
