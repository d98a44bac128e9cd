"""One process against camera stages and a fusion tracker, on the same recording.

:func:`fusion_vs_single` steps two trackers with the same configuration and seed side by
side: one on the images (``input_mode: images``), one fed as a fusion node is
(``input_mode: foreground``): a :class:`~mbtrack_ros.core.detection.camera_stage
.CameraStage` per camera, their masks through
:class:`~mbtrack_ros.core.detection.camera_stage.ReceivedForeground`, the bootstrap regions
sent back, each stage given the fusion tracker's reported tracks after its step (the one
frame of latency of the update). With ``stage_likelihood`` each camera stage also scores
the fusion tracker's particles in its camera (:meth:`CameraStage.score` through
:meth:`MeasurementModel.set_scorers`): the request and its answer are what would travel
between the nodes, their CPU is the stage's. No DDS: the comparison isolates the split
itself.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.core.detection.camera_stage import CameraStage, ReceivedForeground
from mbtrack_ros.core.tracker import Tracker, TrackerConfig
from mbtrack_ros.recording.csvfiles import TrackRow
from mbtrack_ros.recording.images import decode_compressed, encode_compressed

__all__ = ['FusionComparison', 'fusion_vs_single']


@dataclass
class FusionComparison:
    """What :func:`fusion_vs_single` found.

    Attributes:
        frames: frame sets stepped.
        same_ids: frame sets where both reported the same track ids.
        tracked: frame sets where one process reported a track.
        gaps: floor distance, metres, between the two estimates of every id both reported.
        rows: ``'single'`` / ``'fusion'`` -> track rows (for CLEAR MOT).
        cpu: CPU time of this process, seconds, spent in ``'single'`` (the one-process
            tracker's steps), ``'stages'`` (all camera stages, with the JPEG coding of
            ``jpeg_quality``) and ``'fusion'`` (the fusion tracker: the masks handed over,
            JPEG decoding, its steps); the three run one after another.
        fusion_timings: the fusion tracker's step timings summed, wall seconds, without
            the camera stages' scoring: ``'filter'`` (prediction, likelihood in every
            camera or the stages' answers taken, MRF), ``'detect_search'``
            (the search for new people), ``'detect'`` (all detection work, the search
            included), ``'total'``.
        started: frame sets of the start-up: up to and including the first one in which
            every camera stage gave a foreground (the background bootstrap and the people
            cue of the fusion node are in them); ``steady_cpu`` holds the CPU seconds of
            ``'single'``, ``'stages'`` and ``'fusion'`` over the frame sets after it.
        decode: CPU seconds per camera frame the fusion tracker spends to read a camera's
            message, by encoding: ``'mask_png'`` (PNG-coded bit planes decoded),
            ``'mask_raw'`` (the raw plane copied out of the message), ``'image_jpeg'``
            (a quality-90 JPEG working image decoded), ``'image_raw'`` (copied); measured
            on every 10th frame set's frames after the start-up (``decode_frames`` camera
            frames).
        scored: camera requests the stages answered (``stage_likelihood``);
            ``score_bytes`` the bytes of their arrays, ``'request'`` and ``'reply'``.
    """

    frames: int = 0
    same_ids: int = 0
    tracked: int = 0
    gaps: list[float] = field(default_factory=list)
    rows: dict[str, list[TrackRow]] = field(
        default_factory=lambda: {'single': [], 'fusion': []})
    cpu: dict[str, float] = field(
        default_factory=lambda: {'single': 0.0, 'stages': 0.0, 'fusion': 0.0})
    fusion_timings: dict[str, float] = field(
        default_factory=lambda: dict.fromkeys(('filter', 'detect_search', 'detect', 'total'),
                                              0.0))
    started: int | None = None
    steady_cpu: dict[str, float] = field(
        default_factory=lambda: {'single': 0.0, 'stages': 0.0, 'fusion': 0.0})
    decode: dict[str, float] = field(
        default_factory=lambda: dict.fromkeys(('mask_png', 'mask_raw', 'image_jpeg',
                                               'image_raw'), 0.0))
    decode_frames: int = 0
    scored: int = 0
    score_bytes: dict[str, int] = field(
        default_factory=lambda: {'request': 0, 'reply': 0})

    @property
    def steady_frames(self) -> int:
        """Frame sets after the start-up (:attr:`started`)."""
        return 0 if self.started is None else self.frames - self.started


def fusion_vs_single(recording: str | Path, config: TrackerConfig | None = None,
                     reader_options: dict | None = None,
                     jpeg_quality: int | None = None, *,
                     stage_likelihood: bool = True) -> FusionComparison:
    """Track ``recording`` (a recording directory) both ways; see the module docstring.
    ``config`` must enable detection (default: ``TrackerConfig(detection=True, seed=0)``,
    what ``mbtrack replay`` runs without options); ``reader_options``: keyword arguments
    of the :class:`~mbtrack_ros.recording.bag.RecordingReader` (its frame-set
    synchroniser's settings; ``mbtrack replay`` takes the recording's frame rate).
    ``jpeg_quality``: the working images reach the fusion tracker JPEG-coded at this
    quality (``camera_node`` ``image_format: jpeg``), as it decodes them; None: raw.
    ``stage_likelihood``: the camera stages score the particles in their cameras (else
    the fusion tracker scores every camera itself)."""
    from mbtrack_ros.recording.bag import RecordingReader

    recording = Path(recording)
    config = config or TrackerConfig(detection=True, seed=0)
    calibration = RoomCalibration.load(recording / 'calibration.yaml')
    single, fusion = Tracker(calibration, config), Tracker(calibration, config)
    background = fusion.detection.config.background
    bank = ReceivedForeground(fusion.detection.calibration, background)
    fusion.detection.background = bank
    stages = {n: CameraStage(c, background, working_pixels=config.working_pixels)
              for n, c in calibration.cameras.items()}
    out = FusionComparison()
    # thread CPU and wall seconds of the stages' scoring in this frame set
    scoring = [0.0, 0.0]

    def scorer(name: str):
        def score(request):
            t, w = time.thread_time(), time.perf_counter()
            got = stages[name].score(request)
            scoring[0] += time.thread_time() - t   # += of a float: atomic under the GIL
            scoring[1] += time.perf_counter() - w
            if got is not None:
                out.scored += 1
                out.score_bytes['request'] += request.nbytes
                out.score_bytes['reply'] += got.nbytes
            return lambda: got
        return score

    if stage_likelihood:
        fusion.measurement.set_scorers({n: scorer(n) for n in stages})
    with RecordingReader(recording, **(reader_options or {})) as reader:
        for fs in reader.frames():
            t0 = time.process_time()
            a = single.step(fs.stamp_ns, fs.images, stamps=fs.stamps)
            t1 = time.process_time()
            frames = {n: stages[n].process(im) for n, im in fs.images.items()}
            coded = {}
            if jpeg_quality is not None:
                coded = {n: encode_compressed(f.image, 'jpeg', quality=jpeg_quality)
                         for n, f in frames.items()}
            t2 = time.process_time()
            scoring[:] = [0.0, 0.0]
            for n, (fmt, data) in coded.items():   # what a JPEG working image decodes to
                # (the stage keeps its own frame: it scores particles on the raw image)
                frames[n] = replace(frames[n], image=decode_compressed(fmt, data))
            for n, regions in bank.receive(frames).items():
                stages[n].set_regions(*regions)
            b = fusion.step(fs.stamp_ns, {n: f.image for n, f in frames.items()},
                            stamps=fs.stamps)
            t3 = time.process_time() - scoring[0]   # the stages' scoring is theirs
            out.cpu['single'] += t1 - t0
            out.cpu['fusion'] += t3 - t2
            for key in out.fusion_timings:   # without the stages' scoring (the filter's)
                out.fusion_timings[key] += b.timings.get(key, 0.0) \
                    - (scoring[1] if key in ('filter', 'total') else 0.0)
            xy = np.array([t.mean[:2] for t in b.tracks]).reshape(-1, 2)
            velocity = np.array([t.mean[2:4] for t in b.tracks]).reshape(-1, 2)
            heights = np.array([t.height for t in b.tracks])
            t4 = time.process_time()
            for stage in stages.values():      # what ~/tracks gives a camera node
                stage.set_tracks(xy, velocity, heights)
            t5 = time.process_time()
            staged = t2 - t1 + t5 - t4 + scoring[0]
            out.cpu['stages'] += staged
            if out.started is not None:
                for key, dt in (('single', t1 - t0), ('stages', staged), ('fusion', t3 - t2)):
                    out.steady_cpu[key] += dt
                if out.steady_frames % 10 == 0:
                    _time_decoding(frames.values(), out)
            elif all(f.foreground is not None for f in frames.values()):
                out.started = out.frames + 1
            xa = {t.track_id: t.mean[:2] for t in a.tracks}
            xb = {t.track_id: t.mean[:2] for t in b.tracks}
            out.frames += 1
            out.same_ids += sorted(xa) == sorted(xb)
            out.tracked += bool(xa)
            out.gaps += [float(np.hypot(*(xa[i] - xb[i]))) for i in set(xa) & set(xb)]
            for key, result in (('single', a), ('fusion', b)):
                out.rows[key] += [TrackRow(fs.stamp_ns, fs.index, t.track_id,
                                           float(t.mean[0]), float(t.mean[1]))
                                  for t in result.tracks]
    return out


def _time_decoding(frames, out: FusionComparison) -> None:
    """Add to ``out.decode`` the thread CPU seconds of reading each camera frame's masks
    and image as the fusion node receives them, in each encoding (``camera_node``
    ``image_format`` raw: rgb8 image and mono8 plane; jpeg: JPEG image and PNG plane)."""
    import cv2

    from mbtrack_ros.core.detection.camera_stage import pack_masks, unpack_masks

    for f in frames:
        if f.foreground is None:
            continue
        packed = pack_masks(f.foreground, f.possible, f.presence)
        png = cv2.imencode('.png', packed)[1].tobytes()
        plane = packed.tobytes()
        _, jpeg = encode_compressed(f.image, 'jpeg', quality=90)
        image = f.image.tobytes()
        h, w = packed.shape
        for key, read in (
                ('mask_png', lambda: unpack_masks(decode_compressed('png', png))),
                ('mask_raw', lambda: unpack_masks(
                    np.frombuffer(plane, np.uint8).reshape(h, w).copy())),
                ('image_jpeg', lambda: decode_compressed('jpeg', jpeg)),
                ('image_raw', lambda: np.frombuffer(image, np.uint8).reshape(h, w, 3).copy())):
            t = time.thread_time()
            read()
            out.decode[key] += time.thread_time() - t
        out.decode_frames += 1
