"""h-rel, offline on release_probe.py logs (PROBE dir) and main's outputs (BASE dir): per y bin in front of the door, the larger
coverage of cam2/cam3 for tracks matched / unmatched to a person.  usage: doorway_coverage.py RUN..."""
import os
import sys
from pathlib import Path
import numpy as np
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import detection_eval as de
FPS=15
acc={}
for run in sys.argv[1:]:
    out=Path(os.environ.get('PROBE', '/tmp/h-rel/probe'))/run; rec=Path('/tmp/h4')/run.rsplit('_s',1)[0]
    tracks,truth,events,last=de._load(Path(os.environ.get('BASE', '/tmp/h-exit/v3'))/run,rec)
    d,frames=de._matching(tracks,truth)
    pr=np.genfromtxt(out/'probe.csv',delimiter=',',names=True)
    s0=min(r.stamp_ns for r in truth)
    pf=np.round((pr['stamp_ns']-s0)/(1e9/FPS)).astype(int)
    matched={(int(f),int(t)):int(p) for f,t,p in zip(frames,d.track_id,d.person_id) if t>=0 and p>=0}
    gtp={(r.frame,r.person_id):(r.x,r.y) for r in truth}
    wall=np.nanmax(np.stack([pr['coverage_cam2'],pr['coverage_cam3']]),axis=0)
    for i in range(len(pr)):
        x,y=pr['x'][i],pr['y'][i]
        if not(4.2<=x<=5.1 and 4.2<=y<=5.0): continue
        p=matched.get((pf[i],int(pr['track_id'][i])))
        if p is None: lab='unmatched'
        else:
            lab='matched'
        yb=('%.1f'%(np.floor(y*10)/10))
        acc.setdefault((lab,yb),[]).append(wall[i])
for k in sorted(acc):
    w=np.array(acc[k]); print(k, len(w), 'p5/25/50', np.round(np.nanpercentile(w,[5,25,50]),2), '<0.3:', round(np.mean(~(w>=0.3)),2))
