"""Run-by-run comparison of two ``detection_eval.py suite`` outputs (eleventh session).

Usage: compare_scores.py A/scores.json[,A2/scores.json...] B/scores.json[,B2/...]

For the runs (recording, seed) both sides hold (a side may join several suites, e.g. the
seeds 0-4 and the held-out seeds of one tree): on how many B has fewer / more / as many
identity switches as A, and higher / lower MOTA, and each run whose switches differ; then
the totals of each (switches, mean MOTA and MOTP, runs within the target), the switches
per tracker seed (all recordings together), on how many seeds B has fewer / more, and
Welch's t and the Mann-Whitney test of those per-seed totals (scipy).
"""
import json
import sys

from scipy import stats

from _eval import detection_eval

if len(sys.argv) != 3:
    sys.exit('usage: compare_scores.py A/scores.json[,...] B/scores.json[,...]')
a, b = ({(r['recording'], r['seed']): r for p in arg.split(',')
         for r in json.load(open(p, encoding='utf-8'))['runs']} for arg in sys.argv[1:])
both = sorted(a.keys() & b.keys())
if not both:
    sys.exit('compare_scores: no run in common')
sw = [b[k]['mismatches'] - a[k]['mismatches'] for k in both]
mota = [b[k]['mota'] - a[k]['mota'] for k in both]
print(f'{len(both)} runs: switches fewer in B on {sum(v < 0 for v in sw)}, more on '
      f'{sum(v > 0 for v in sw)}, equal on {sum(v == 0 for v in sw)}; MOTA higher on '
      f'{sum(v > 0 for v in mota)}, lower on {sum(v < 0 for v in mota)}')
for k, v in zip(both, sw):
    if v:
        print(f'  {k[0]} seed {k[1]}: {a[k]["mismatches"]} -> {b[k]["mismatches"]} switches')
seeds = sorted({k[1] for k in both})
per_seed = {}
met = detection_eval._meets_switch_target   # the suite's own test of the target
for name, runs in (('A', a), ('B', b)):
    per_seed[name] = [sum(runs[k]['mismatches'] for k in both if k[1] == s) for s in seeds]
    print(f'{name}: {sum(runs[k]["mismatches"] for k in both)} switches, mean MOTA '
          f'{100 * sum(runs[k]["mota"] for k in both) / len(both):.2f} %, mean MOTP '
          f'{sum(runs[k]["motp_mm"] for k in both) / len(both):.1f} mm, runs within '
          f'{detection_eval.SWITCH_TARGET:g} switches per person '
          f'{sum(met(runs[k]["switches_per_person"]) for k in both)}'
          f'; per tracker seed '
          f'{seeds}: {per_seed[name]}')
fell = sum(b_ < a_ for a_, b_ in zip(per_seed['A'], per_seed['B']))
rose = sum(b_ > a_ for a_, b_ in zip(per_seed['A'], per_seed['B']))
print(f'per tracker seed, B against A: fewer switches on {fell} of {len(seeds)} seeds, '
      f'more on {rose}')
if len(seeds) > 1:
    welch = stats.ttest_ind(per_seed['B'], per_seed['A'], equal_var=False)
    ranks = stats.mannwhitneyu(per_seed['B'], per_seed['A'])
    print(f'per-seed switches, B against A: Welch t = {welch.statistic:.2f} '
          f'(p = {welch.pvalue:.2f}), Mann-Whitney p = {ranks.pvalue:.2f}')
