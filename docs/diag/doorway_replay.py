"""h-rel, offline: replay 'in the doorway band, support only from the exit-blind cameras' with timeout T on release_probe.py logs.
    usage: doorway_replay.py BAND TIMEOUT MIN_COVERAGE RUN...  (RUN = rec_sS; PROBE, BASE dirs)"""
import os
import sys
from pathlib import Path
import numpy as np
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import detection_eval as de
FPS=15
band=float(sys.argv[1]); T=int(round(float(sys.argv[2])*FPS)); thr=float(sys.argv[3]); runs=sys.argv[4:]
tot={}
for run in runs:
    out=Path(os.environ.get('PROBE', '/tmp/h-rel/probe'))/run; rec=Path('/tmp/h4')/run.rsplit('_s',1)[0]
    tracks,truth,events,last=de._load(Path(os.environ.get('BASE', '/tmp/h-exit/v3'))/run,rec)
    d,frames=de._matching(tracks,truth)
    pr=np.genfromtxt(out/'probe.csv',delimiter=',',names=True)
    s0=min(r.stamp_ns for r in truth)
    pf=np.round((pr['stamp_ns']-s0)/(1e9/FPS)).astype(int)
    matched={(int(f),int(t)):int(p) for f,t,p in zip(frames,d.track_id,d.person_id) if t>=0 and p>=0}
    present={(r.frame,r.person_id) for r in truth}
    ends={}
    for e in events:
        if e['kind']=='end': ends.setdefault(e['id'],[]).append(e['frame'])
    wall=np.nanmax(np.stack([pr['coverage_cam2'],pr['coverage_cam3']]),axis=0)
    inb=(pr['x']>=4.2)&(pr['x']<=5.1)&(pr['y']>=4.7-band)&(pr['y']<=5.0)
    bad=inb&~(wall>=thr)
    res=[]
    for tid in np.unique(pr['track_id']):
        s=np.flatnonzero(pr['track_id']==tid)
        run_len=0; prevf=None
        for i in s:
            f=pf[i]
            if prevf is not None and f!=prevf+1: run_len=0   # id reused / gap
            prevf=f
            run_len = run_len+1 if bad[i] else 0
            if run_len>=T:
                endf=min([g for g in ends.get(int(tid),[]) if g>=f], default=None)
                ps=[matched[(g,int(tid))] for g in range(f-15,f) if (g,int(tid)) in matched]
                if not ps: kind='nobody'
                else:
                    p=int(np.bincount(ps).argmax())
                    n=sum((g,p) in present for g in range(f+1,f+16))
                    kind='premature' if n>=10 else 'left'
                gain=(endf-f)/FPS if endf is not None else np.nan
                res.append((int(tid),f,kind,gain))
                tot[kind]=tot.get(kind,0)+1
                tot[kind+'_gain']=tot.get(kind+'_gain',0)+gain
                break
    print(run, ' '.join(f'{t}@{f}:{k}:{g:+.1f}s' for t,f,k,g in res))
print({k:(round(v,1) if 'gain' in k else v) for k,v in tot.items()})
