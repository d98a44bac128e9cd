"""Timeline of each entering person: GT first row, crossings, camera visibility, the
detection decisions near them, births and the first reported / matched frame."""
import sys
from pathlib import Path
import os
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # docs/ for detection_eval
RECS = Path(os.environ.get('MBTRACK_RECS', '/tmp/h4'))  # the cached clear-room recordings
import numpy as np
import detection_eval as de
from mbtrack_ros.evaluation.clear_mot import clear_mot
late_only = '--all' not in sys.argv
roots = [a for a in sys.argv[1:] if not a.startswith('--')]
for root in roots:
  for rec in ['cr2','cr3','crnc1','crnc2','crnc3','cr1']:
    for s in (0, 1):
        out = Path(root) / f'{rec}_s{s}'
        if not (out / 'events.json').exists():
            continue
        tracks, truth, events, last = de._load(out, RECS / rec)
        d = clear_mot(tracks, truth).matches_detail
        s0 = min(r.stamp_ns for r in truth)
        fr = np.round((d.stamp_ns.astype(np.int64) - s0) / (1e9 / 15)).astype(int)
        per = {}
        for r in truth:
            per.setdefault(r.person_id, []).append(r)
        first_row = {}
        for t in tracks:
            first_row.setdefault(t.track_id, t)
        births = {e['id']: e['frame'] for e in events if e['kind'] == 'birth'}
        for p, rows in per.items():
            rows.sort(key=lambda r: r.frame)
            if rows[0].frame == 0:
                continue
            sel = (d.person_id == p) & (d.track_id >= 0)
            if not sel.any():
                continue
            fm = int(fr[sel].min()); tm = int(d.track_id[sel][np.argmin(fr[sel])])
            lat = (fm - rows[0].frame) / 15
            if late_only and lat <= 0.5:
                continue
            f0 = rows[0].frame
            def first(cond):
                return next((r.frame for r in rows if cond(r)), None)
            side2 = first(lambda r: len([c for c in r.visible_cameras if c != 'cam4']) >= 2)
            edge = first(lambda r: r.y <= 4.85)
            floor = first(lambda r: r.y <= 4.7)
            print(f'{out.name} person {p}: latency {lat:.2f} s; first row f{f0} ({rows[0].x:.2f},{rows[0].y:.2f}) cams {"/".join(rows[0].visible_cameras)}; 2 side cams f{side2}; y<=4.85 f{edge}; y<=4.7 f{floor}; matched f{fm} track {tm} born f{births.get(tm)} first reported f{first_row[tm].frame}')
            byf = {r.frame: r for r in rows}
            for e in events:
                if e['kind'] == 'decision' and f0 - 5 <= e['frame'] <= fm:
                    r = byf.get(e['frame'])
                    dd = np.hypot(r.x - e['xy'][0], r.y - e['xy'][1]) if r else np.nan
                    if dd < 1.0:
                        print(f'    f{e["frame"]} decision {e["action"]} at ({e["xy"][0]:.2f},{e["xy"][1]:.2f}) {dd:.2f} m from p; near {e.get("near")}')
            # other GT people near the door at f0..fm
            for f in range(f0, fm + 1, 3):
                r = byf.get(f)
                if r is None: continue
                others = [o for o in truth if o.frame == f and o.person_id != p and np.hypot(o.x - r.x, o.y - r.y) < 1.0]
                trk = [(t.track_id, round(float(np.hypot(t.x - r.x, t.y - r.y)), 2)) for t in tracks if t.frame == f and np.hypot(t.x - r.x, t.y - r.y) < 1.0]
                print(f'      f{f} p at ({r.x:.2f},{r.y:.2f}) cams {"/".join(r.visible_cameras)}; others <1m {[(o.person_id, round(float(np.hypot(o.x-r.x,o.y-r.y)),2)) for o in others]}; tracks <1m {trk}')
