"""Run-by-run comparison of two ``detection_eval.py suite`` outputs (eleventh session).

Usage: compare_scores.py A/scores.json B/scores.json

For the runs (recording, seed) both hold: on how many B has fewer / more / as many
identity switches as A, and higher / lower MOTA; then the totals of each.
"""
import json
import sys

if len(sys.argv) != 3:
    sys.exit('usage: compare_scores.py A/scores.json B/scores.json')
a, b = ({(r['recording'], r['seed']): r for r in json.load(open(p, encoding='utf-8'))['runs']}
        for p in sys.argv[1:])
both = sorted(a.keys() & b.keys())
if not both:
    sys.exit('compare_scores: no run in common')
sw = [b[k]['mismatches'] - a[k]['mismatches'] for k in both]
mota = [b[k]['mota'] - a[k]['mota'] for k in both]
print(f'{len(both)} runs: switches fewer in B on {sum(v < 0 for v in sw)}, more on '
      f'{sum(v > 0 for v in sw)}, equal on {sum(v == 0 for v in sw)}; MOTA higher on '
      f'{sum(v > 0 for v in mota)}, lower on {sum(v < 0 for v in mota)}')
for name, runs in (('A', a), ('B', b)):
    print(f'{name}: {sum(runs[k]["mismatches"] for k in both)} switches, mean MOTA '
          f'{100 * sum(runs[k]["mota"] for k in both) / len(both):.2f} %')
