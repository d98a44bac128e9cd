"""How fast the filter picks up a painted person who starts walking (h-exist)."""
import sys; sys.path.insert(0, 'test')
import numpy as np, test_detection as T
from dataclasses import replace
speed = float(sys.argv[1]); reach = float(sys.argv[2])
rng = np.random.default_rng(5); calib = T.make_room(ceiling=False); bgs = T.backgrounds(calib)
tracker = T._detecting_tracker(calib, bgs, seed=4)
tracker.detection.config = replace(tracker.detection.config, reach_radius=reach)
def x_at(k): return 1.5 + speed * max(k - 20, 0) / T.FPS
walker = lambda k: [T.person(x_at(k), 2.6, theta=0.0)]
for k in range(50):
    r = tracker.step(int(round(k * 1e9 / T.FPS)), T.paint(calib, bgs, walker(k), rng))
    if k >= 16:
        tr = {t.track_id: t for t in r.tracks}
        s = ' '.join(f'id{t.track_id} lag {x_at(k) - t.mean[0]:+.2f} vx {t.mean[2]:+.2f} ex {t.existence:.2f}' for t in r.tracks)
        print(k, f'{x_at(k):.2f}', s or 'none', tracker.track_ids)
