"""Frame generation: crowd simulation + ray-cast rendering + image formation + ground truth.

Per frame and camera: copy the static radiance and depth buffers, redraw the wall screen and
the door pixels, ray-cast every body ellipsoid inside its projected bounding box (compiled
kernel, z-tested, writing a person-id buffer), then apply the camera response: per-camera
channel gains, a slow global illumination drift and Gaussian sensor noise (sigma 2.5 grey
levels, slices of a noise bank drawn once from the generator), quantised to uint8.

Ground truth per present person inside the walls: floor point under the pelvis, top of the
head, sitting (pose blend > 0.5) and the cameras where at least ``30 * W * H / (320 * 240)``
of its pixels are visible in the id buffer.
"""
from __future__ import annotations

import math
import threading
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path
from queue import Queue

import numpy as np
import yaml

from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.recording.csvfiles import GroundTruthRow, write_ground_truth
from mbtrack_ros.synth.body import Ellipsoids, pose_ellipsoids
from mbtrack_ros.synth.conditions import PRESET_CONDITIONS, Conditions, conditions_rng
from mbtrack_ros.synth.errors import SynthError
from mbtrack_ros.synth.motion import PersonState
from mbtrack_ros.synth.presets import Preset, get_preset, populate
from mbtrack_ros.synth.raster import draw_ellipsoids, expose
from mbtrack_ros.synth.shadows import cast_shadows
from mbtrack_ros.synth.room import CameraView, Room, make_calibration

__all__ = ['EPOCH_NS', 'SynthFrame', 'Synthesizer', 'generate', 'iter_frames',
           'render_view', 'visible_threshold']

EPOCH_NS = 1_700_000_000 * 1_000_000_000
NOISE_SIGMA = 2.5


@dataclass
class SynthFrame:
    """One synthetic frame set.

    Attributes:
        index: frame number from 0.
        stamp_ns: integer nanoseconds, ``EPOCH_NS + index * round(1e9 / fps)``.
        images: camera name -> (H, W, 3) uint8 RGB.
        ground_truth: one row per person inside the room.
        id_buffers: camera name -> (H, W) int16 person id per pixel (0 = none).
        people: states of all present people (also those still in the corridor).
        stamps: camera name -> capture time of its image, ns (``stamp_ns`` unless the
            cameras are free-running, :class:`~mbtrack_ros.synth.conditions.Conditions`).
    """

    index: int
    stamp_ns: int
    images: dict[str, np.ndarray]
    ground_truth: list[GroundTruthRow]
    id_buffers: dict[str, np.ndarray] = field(repr=False)
    people: list[PersonState] = field(default_factory=list, repr=False)
    door_angle: float = 0.0
    stamps: dict[str, int] = field(default_factory=dict)

    def __iter__(self) -> Iterator:
        """Unpacks as ``stamp_ns, images, ground_truth``."""
        return iter((self.stamp_ns, self.images, self.ground_truth))


def visible_threshold(width: int, height: int) -> int:
    """Visible pixels a person needs in a camera to count as seen: 30 at 320 x 240."""
    return max(1, int(round(30.0 * width * height / (320 * 240))))


def _bboxes(view: CameraView, ell: Ellipsoids) -> np.ndarray:
    """(P, 4) int pixel windows ``u0, v0, u1, v1`` covering each projected ellipsoid.

    The window bounds the projected corners of the ellipsoid's oriented bounding box plus a
    margin of 2 px + 5 % (lens distortion bends the box edges slightly).
    """
    cam = view.camera
    pix = cam.project(ell.corners())  # (P, 8, 2), NaN behind the camera
    behind = np.isnan(pix[..., 0])
    if behind.any():
        lo = np.where(behind[..., None], np.inf, pix).min(axis=1)
        hi = np.where(behind[..., None], -np.inf, pix).max(axis=1)
    else:
        lo, hi = pix.min(axis=1), pix.max(axis=1)
    margin = 2.0 + 0.05 * (hi - lo)
    box = np.concatenate([np.floor(lo - margin), np.ceil(hi + margin) + 1], axis=1)
    limit = np.array([cam.width, cam.height, cam.width, cam.height], dtype=np.float64)
    with np.errstate(invalid='ignore'):
        out = np.clip(np.nan_to_num(box, nan=0.0, posinf=0.0, neginf=0.0), 0, limit)
    out = out.astype(np.int64)
    if behind.any():
        partly = behind.any(axis=1) & ~behind.all(axis=1)
        out[partly] = (0, 0, cam.width, cam.height)  # straddles the camera plane: scan all
        out[behind.all(axis=1)] = 0                    # entirely behind: skip
    return out


def render_view(view: CameraView, ellipsoids: Ellipsoids, *, time_s: float = 0.0,
                door_angle: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Render one camera before the camera response.

    Returns:
        radiance (H, W, 3) float32 0..255, depth (H, W) float32 metres along the ray,
        ids (H, W) int16 owner ids (0 = room).
    """
    radiance = view.radiance.copy()
    depth = view.depth.copy()
    ids = np.zeros(depth.shape, dtype=np.int16)
    flat_r = radiance.reshape(-1, 3)
    flat_d = depth.reshape(-1)
    if view.screen_index.size:
        flat_r[view.screen_index] = view.screen_update(time_s)
    if view.door_index.size and door_angle > 0.0:  # the closed door is in the static image
        rad, dep = view.door_update(float(door_angle))
        flat_r[view.door_index] = rad
        flat_d[view.door_index] = dep
    if len(ellipsoids.centers):
        cam = view.camera
        room = view.room
        draw_ellipsoids(view.rays, cam.center, depth, radiance, ids, ellipsoids.to_unit,
                        ellipsoids.axes, ellipsoids.radii, ellipsoids.centers,
                        _bboxes(view, ellipsoids), ellipsoids.owner.astype(np.int16),
                        ellipsoids.colour1, ellipsoids.colour2,
                        ellipsoids.texture.astype(np.int64), ellipsoids.frequency,
                        np.asarray(room.light, dtype=np.float64), room.ambient, room.diffuse)
    return radiance, depth, ids


_BASE_PIXELS = 320 * 240 * 3   # values of the default image size


class Synthesizer:
    """A preset rendered frame by frame (deterministic for a seed).

    Args:
        preset: a preset name (see :data:`PRESETS`) or a :class:`Preset`.
        seed: seed of the single ``np.random.Generator`` behind all randomness.
        frames: number of frames (default: the preset's).
        width, height: image size in pixels; fps: frame rate (Hz).
        ceiling: include the ceiling camera where the preset uses all cameras.
        conditions: real-room conditions (:mod:`mbtrack_ros.synth.conditions`; default:
            the preset's own, none for most presets).
    """

    def __init__(self, preset: str | Preset, *, seed: int = 0, frames: int | None = None,
                 width: int = 320, height: int = 240, fps: float = 15.0,
                 ceiling: bool = True, room: Room | None = None,
                 conditions: Conditions | None = None) -> None:
        self.preset = get_preset(preset) if isinstance(preset, str) else preset
        self.conditions = conditions if conditions is not None else \
            PRESET_CONDITIONS.get(self.preset.name, Conditions())
        self.frames = self.preset.frames if frames is None else int(frames)
        if self.frames <= 0:
            raise SynthError(f'frames must be positive, got {frames}')
        if not fps > 0 or not math.isfinite(fps):
            raise SynthError(f'fps must be positive, got {fps}')
        self.fps = float(fps)
        self.period_ns = int(round(1e9 / self.fps))  # constant integer frame period
        self.seed = int(seed)
        self.width, self.height = int(width), int(height)
        self.room = room or self.preset.room()
        self.calibration: RoomCalibration = make_calibration(
            self.room, width=self.width, height=self.height,
            ceiling=ceiling and self.preset.ceiling, cameras=self.preset.cameras)
        self.views = {n: CameraView.build(c, self.room)
                      for n, c in self.calibration.cameras.items()}
        self.rng = np.random.default_rng(self.seed)
        rng = self.rng
        n_cam = len(self.views)
        # per-camera colour response: overall gain x channel gains; illumination drift
        self.gains = (rng.uniform(0.85, 1.15, (n_cam, 1))
                      * rng.uniform(0.92, 1.08, (n_cam, 3))).astype(np.float32)
        self.drift_period = rng.uniform(25.0, 50.0, 2)
        self.drift_phase = rng.uniform(0, 2 * np.pi, 2)
        pixels = self.width * self.height * 3
        # the main stream draws what it draws at 320x240 whatever the size, so a seed gives
        # the same people and motion at every resolution; other sizes take their sensor
        # noise from a stream of their own
        bank = rng.standard_normal(4 * _BASE_PIXELS)
        if pixels != _BASE_PIXELS:
            bank = np.random.default_rng([self.seed, self.width, self.height]) \
                .standard_normal(4 * pixels)
        self.noise_bank = (NOISE_SIGMA * bank).astype(np.float32)
        self.crowd = populate(self.preset, self.room, rng)
        self.threshold = visible_threshold(self.width, self.height)
        crng = conditions_rng(self.seed)
        #: per camera, how long before the frame's time it captures, ns (free-running)
        self.capture_leads_ns = {
            n: int(round(lead * self.period_ns))
            for n, lead in zip(self.views, self.conditions.capture_leads(n_cam, crng))}
        self._exposure = self.conditions.exposure(n_cam, crng)
        self._poses: dict[int, tuple] = {}
        self._started = False
        self._pool = ThreadPoolExecutor(max_workers=min(2, len(self.views)),
                                        thread_name_prefix='synth-render')

    def stamp_ns(self, index: int) -> int:
        """Exact integer stamp of frame ``index``."""
        return EPOCH_NS + index * self.period_ns

    def illumination(self, time_s: float) -> float:
        """Global slow illumination factor (about 0.9 .. 1.1)."""
        return float(1.0 + 0.06 * np.sin(2 * np.pi * time_s / self.drift_period[0]
                                         + self.drift_phase[0])
                     + 0.03 * np.sin(2 * np.pi * time_s / self.drift_period[1]
                                     + self.drift_phase[1]))

    def __iter__(self) -> Iterator[SynthFrame]:
        """Render the frames in order (a Synthesizer can be iterated once)."""
        if self._started:
            raise SynthError('a Synthesizer renders its frames once; make a new one')
        self._started = True
        return self._frames()

    def _frames(self) -> Iterator[SynthFrame]:
        dt = 1.0 / self.fps
        pixels = self.width * self.height * 3
        before: dict[int, tuple[float, float]] = {}   # positions at the previous frame
        for index in range(self.frames):
            if index:
                before = {p.person_id: (p.x, p.y) for p in self.crowd.people()}
                self.crowd.step(dt)
            time_s = index * dt
            people = self.crowd.people()
            bodies, tops, poses = [], {}, {}
            for person in people:
                key = (person.x, person.y, person.theta, person.phase, person.stride,
                       person.sit)
                cached = self._poses.get(person.person_id)
                if cached is not None and cached[0] == key:  # standing still or seated
                    ell, top = cached[1], cached[2]
                else:
                    ell, top = pose_ellipsoids(person.height, person.clothing, x=person.x,
                                               y=person.y, theta=person.theta,
                                               phase=person.phase, stride=person.stride,
                                               sit=person.sit, owner=person.person_id)
                poses[person.person_id] = (key, ell, top)
                bodies.append(ell)
                tops[person.person_id] = top
            self._poses = poses
            ellipsoids = Ellipsoids.concat(bodies)
            light = self.illumination(time_s) * self.conditions.light(time_s)
            lamps = self.conditions.lamp_positions(self.room)
            offsets = self.rng.integers(0, 3 * _BASE_PIXELS, len(self.views))
            if pixels != _BASE_PIXELS:   # the same draws, spread over this size's bank
                offsets = offsets * pixels // _BASE_PIXELS
            door = self.crowd.door_angle

            def at_capture(name: str) -> Ellipsoids:
                """The bodies where they were when camera ``name`` captured (its lead
                before the frame's time: positions interpolated from the last frame)."""
                lead = self.capture_leads_ns[name] / self.period_ns
                if lead == 0 or not before:
                    return ellipsoids
                moved = []
                for person, ell in zip(people, bodies):
                    x0, y0 = before.get(person.person_id, (person.x, person.y))
                    shift = np.array([(x0 - person.x) * lead, (y0 - person.y) * lead, 0.0])
                    moved.append(replace(ell, centers=ell.centers + shift))
                return Ellipsoids.concat(moved)

            def shoot(k: int, view: CameraView) -> tuple[np.ndarray, np.ndarray]:
                bodies_then = at_capture(view.camera.name)
                radiance, depth, ids = render_view(view, bodies_then, time_s=time_s,
                                                   door_angle=door)
                if lamps is not None:   # cast shadows (conditions.lamps)
                    cast_shadows(view.rays, view.camera.center, depth, ids, radiance,
                                 lamps[0], lamps[1], bodies_then)
                gain = self.gains[k] * light * np.float32(self._exposure(k, time_s))
                return expose(radiance, gain.astype(np.float32), self.noise_bank,
                              int(offsets[k])), ids

            # cameras are independent: render them on two threads (compiled kernels release
            # the GIL); all random numbers were drawn above, so the output is deterministic
            shots = list(self._pool.map(shoot, range(len(self.views)), self.views.values()))
            images = {n: shot[0] for n, shot in zip(self.views, shots)}
            id_buffers = {n: shot[1] for n, shot in zip(self.views, shots)}
            counts = {n: np.bincount(ids.ravel(), minlength=self.crowd.next_id)
                      for n, ids in id_buffers.items()}
            stamp = self.stamp_ns(index)
            rows = []
            for person in people:
                if not self.room.inside(np.array([person.x, person.y])):
                    continue
                cams = tuple(n for n in self.views if counts[n][person.person_id]
                             >= self.threshold)
                rows.append(GroundTruthRow(stamp, index, person.person_id, person.x, person.y,
                                           tops[person.person_id], person.sit > 0.5, cams))
            stamps = {n: stamp - self.capture_leads_ns[n] for n in self.views}
            yield SynthFrame(index, stamp, images, rows, id_buffers, people, door, stamps)
        self._pool.shutdown(wait=False)


def iter_frames(preset: str | Preset, *, seed: int = 0, frames: int | None = None,
                width: int = 320, height: int = 240, fps: float = 15.0,
                ceiling: bool = True) -> Iterator[SynthFrame]:
    """Render a preset frame by frame without writing anything (see :class:`Synthesizer`)."""
    return iter(Synthesizer(preset, seed=seed, frames=frames, width=width, height=height,
                            fps=fps, ceiling=ceiling))


def generate(preset: str | Preset, outdir: str | Path, *, seed: int = 0,
             frames: int | None = None, width: int = 320, height: int = 240,
             fps: float = 15.0, ceiling: bool = True, compressed: bool = False,
             storage: str = 'mcap', progress: bool = False,
             conditions: Conditions | None = None) -> Path:
    """Write a recording directory: ``bag/``, calibration.yaml, ground_truth.csv,
    recording.yaml. ``outdir`` must not exist or be empty. Returns ``outdir``.
    """
    from mbtrack_ros.recording.bag import BagError, RecordingWriter

    outdir = Path(outdir)
    if outdir.exists() and not outdir.is_dir():
        raise SynthError(f'output directory {outdir} exists and is not a directory')
    if outdir.exists() and any(outdir.iterdir()):
        raise SynthError(f'output directory {outdir} exists and is not empty')
    if storage not in ('mcap', 'sqlite3'):
        raise SynthError(f'unknown storage {storage!r} (mcap or sqlite3)')
    synth = Synthesizer(preset, seed=seed, frames=frames, width=width, height=height,
                        fps=fps, ceiling=ceiling, conditions=conditions)
    outdir.mkdir(parents=True, exist_ok=True)
    synth.calibration.save(outdir / 'calibration.yaml')
    if any(synth.conditions.calibration_error):   # what the user's calibration says
        synth.conditions.perturbed(synth.calibration, np.random.default_rng(
            [synth.seed, 0xCA1])).save(outdir / 'calibration_perturbed.yaml')
    rows: list[GroundTruthRow] = []
    frames_iter: Iterator[SynthFrame] = iter(synth)
    if progress:
        from tqdm import tqdm
        frames_iter = tqdm(frames_iter, total=synth.frames, unit='frame',
                           desc=f'synth {synth.preset.name}')
    # The bag is written by a second thread so that serialising, JPEG encoding and disk
    # I/O overlap with rendering (frames are produced in order, so output is deterministic).
    # The writer lives entirely in that thread (sqlite3 connections are thread-bound).
    queue: Queue = Queue(maxsize=8)
    failure: list[BaseException] = []

    def consume() -> None:
        try:
            with RecordingWriter(outdir / 'bag', synth.calibration, storage=storage,
                                 compressed=compressed) as writer:
                while (item := queue.get()) is not None:
                    writer.write_frame(item.stamp_ns, item.images, stamps=item.stamps)
                    writer.write_ground_truth(item.stamp_ns, item.ground_truth)
                return
        except BaseException as err:  # reported in the main thread
            failure.append(err)
        while queue.get() is not None:  # drain so that the producer never blocks
            pass

    thread = threading.Thread(target=consume, name='synth-bag-writer', daemon=True)
    thread.start()
    try:
        for frame in frames_iter:
            if failure:
                break
            queue.put(frame)
            rows.extend(frame.ground_truth)
    finally:
        queue.put(None)
        thread.join()
    if failure:
        err = failure[0]
        if isinstance(err, (BagError, OSError)):
            raise SynthError(f'cannot write the bag: {err}') from err
        raise err
    write_ground_truth(outdir / 'ground_truth.csv', rows)
    meta = {'preset': synth.preset.name, 'description': synth.preset.description,
            'seed': synth.seed, 'frames': synth.frames, 'fps': synth.fps,
            'width': synth.width, 'height': synth.height,
            'size': {n: [synth.width, synth.height] for n in synth.calibration.cameras},
            'cameras': list(synth.calibration.cameras), 'compressed': bool(compressed),
            'storage': storage, 'people': int(synth.crowd.next_id - 1),
            'epoch_ns': EPOCH_NS, 'period_ns': synth.period_ns}
    if synth.conditions.active:
        meta['conditions'] = synth.conditions.to_dict()
        meta['capture_lead_ns'] = dict(synth.capture_leads_ns)
    (outdir / 'recording.yaml').write_text(yaml.safe_dump(meta, sort_keys=False),
                                           encoding='utf-8')
    return outdir
