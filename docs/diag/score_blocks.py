"""Per recording and block of tracker seeds, the switches summed over the block's runs and
the range of their MOTA, as a markdown table (``detection_eval.py suite`` outputs; several
suites may be joined with commas; forty-first session).

usage: .venv/bin/python docs/diag/score_blocks.py A/scores.json[,B/scores.json...] FIRST-LAST...
e.g.   score_blocks.py S1/scores.json,S2/scores.json 0-9 10-14 65-69
"""
import json
import sys

if len(sys.argv) < 3:
    sys.exit(__doc__.split('\n\n')[1])
runs = [r for p in sys.argv[1].split(',') for r in json.load(open(p, encoding='utf-8'))['runs']]
blocks = []
for text in sys.argv[2:]:
    first, _, last = text.partition('-')
    blocks.append((text, range(int(first), int(last or first) + 1)))
print('| recording (people) | ' + ' | '.join(f'seeds {b}' for b, _ in blocks) + ' |')
print('| --- |' + ' --- |' * len(blocks))
for rec in sorted({r['recording'] for r in runs}):
    mine = [r for r in runs if r['recording'] == rec]
    cells = []
    for _, seeds in blocks:
        sel = [r for r in mine if r['seed'] in seeds]
        cells.append('-' if not sel else
                     f'{sum(r["mismatches"] for r in sel)} / '
                     f'{100 * min(r["mota"] for r in sel):.1f}-'
                     f'{100 * max(r["mota"] for r in sel):.1f} %')
    print(f'| {rec} ({mine[0]["people"]}) | ' + ' | '.join(cells) + ' |')
