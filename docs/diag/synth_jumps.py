"""Frame-to-frame jumps of the synthetic people (no rendering).

Usage: synth_jumps.py FIRST_SEED LAST_SEED [THRESHOLD_M]

Steps the clear-room crowd of each seed in [FIRST_SEED, LAST_SEED), with and without the
ceiling camera, exactly as ``mbtrack synth`` does (the renderer's per-frame random draws
included, so the crowd is the rendered one), and prints every step longer than THRESHOLD_M
(default 0.12 m; walking at the top speed of 1.5 m/s is 0.1 m per frame at 15 fps): frame,
person, step, place.
"""
import sys

import numpy as np

from mbtrack_ros.synth.generator import Synthesizer

first, last = int(sys.argv[1]), int(sys.argv[2])
threshold = float(sys.argv[3]) if len(sys.argv) > 3 else 0.12
for seed in range(first, last):
    for ceiling in (True, False):
        synth = Synthesizer('clear-room', seed=seed, ceiling=ceiling)
        dt = 1.0 / synth.fps
        last_xy, jumps = {}, []
        for index in range(synth.frames):
            if index:
                synth.crowd.step(dt)
            # the generator's draw of this frame's noise offsets (same random stream)
            synth.rng.integers(0, 3 * synth.width * synth.height * 3, len(synth.views))
            for p in synth.crowd.people():
                if p.person_id in last_xy:
                    step = float(np.hypot(p.x - last_xy[p.person_id][0],
                                          p.y - last_xy[p.person_id][1]))
                    if step > threshold:
                        jumps.append(f'f{index} person {p.person_id} {step:.2f} m at '
                                     f'({p.x:.2f}, {p.y:.2f})')
                last_xy[p.person_id] = (p.x, p.y)
        synth._pool.shutdown()
        print(f'seed {seed}{"" if ceiling else " --no-ceiling"}: {len(jumps)} jumps',
              *jumps, sep='\n  ')
