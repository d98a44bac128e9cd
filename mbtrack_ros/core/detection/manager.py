"""Automatic detection, acquisition, release and visibility/existence around a tracker.

:class:`AutoDetection` is what :class:`~mbtrack_ros.core.tracker.Tracker` calls after each
filter step when automatic detection is enabled:

1. render the current tracks (posterior means) in every camera; the union is excluded from
   the background update and treated as *unknown* by the detector;
2. update the background models and extract the foreground (003 §4.2);
3. per track: foreground support and the visibility/existence processes (001 §3), from
   the appearance likelihood of a few posterior particles per camera against a clutter
   likelihood, and the coverage of the rendered silhouette;
4. release tracks without support (003 §4.3);
5. search new people away from the remaining tracks (003 §4.1), confirm them over a few
   frames and acquire their appearance models; the tracker then adds them.

Its parts by role: the parameters in :mod:`.config`, what a confirmed detection is (birth,
move, re-identification, drop) in :mod:`.association` with the appearance ratio of
:mod:`.likeness` (its samples taken here, :meth:`AutoDetection._calibrate`), the existence
evidence, duplicate and exit judgements in :mod:`.deleter`; this module wires them with
the background, detector, acquisition and release.
"""
from __future__ import annotations

import logging
import time
from collections.abc import Mapping, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from typing import NamedTuple

import numpy as np

from mbtrack_ros.core.appearance import PersonModel, model_distance, quantize
from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.core.detection import DetectionError
from mbtrack_ros.core.detection.acquisition import acquire
from mbtrack_ros.core.detection.adaptation import adapt_models
from mbtrack_ros.core.detection.association import DetectionAssociator
from mbtrack_ros.core.detection.background import BackgroundBank
from mbtrack_ros.core.detection.camera_stage import exclusion_mask, head_heights
from mbtrack_ros.core.detection.config import AutoDetectionConfig, Birth
from mbtrack_ros.core.detection.deleter import TrackDeleter
from mbtrack_ros.core.detection.detector import Detection, Detector, FrameEvidence, is_ceiling
from mbtrack_ros.core.detection.likeness import AppearanceRatio
from mbtrack_ros.core.detection.release import Releaser
from mbtrack_ros.core.existence import TrackAuxiliary
from mbtrack_ros.core.likelihood import LikelihoodConfig
from mbtrack_ros.core.shape import BodyShape, rasterize, render_labels, width_scale
from mbtrack_ros.core.state import X, Y, TrackEstimate

__all__ = ['AutoDetection', 'AutoDetectionConfig', 'Birth']

_log = logging.getLogger(__name__)

CALIBRATION_INTERVAL = 1.0   # seconds between two appearance calibration samples of a track


class _Pending(NamedTuple):
    """What :meth:`AutoDetection.search` needs from the last :meth:`AutoDetection.update`."""

    stamp_ns: int
    images: Mapping[str, np.ndarray]
    tracks: Sequence[TrackEstimate]
    models: Mapping[int, PersonModel]
    means: np.ndarray
    shapes: list
    evidence: dict
    ended: list


class _Found(NamedTuple):
    """What the compute part of the search found on a pending frame (:meth:`AutoDetection
    ._find`): confirmed detections with their acquired models, and its timings."""

    acquired: list[tuple[Detection, PersonModel]]
    timings: dict[str, float]
    ghosts: tuple[tuple[Detection, float, float], ...] = ()  # (detection, model, frame
    #                                                          outline gradient) of ghosts


class AutoDetection(DetectionAssociator, TrackDeleter):
    """Per-frame background, detection, acquisition, release and existence bookkeeping.

    Args:
        calibration: the room.
        config: pipeline parameters.
        sigma: the appearance likelihood width (003 Eq. 3; 000 Eq. 19), the tracking
            filter's (default ``LikelihoodConfig.sigma``).

    The pipeline draws no random numbers: it is deterministic given the tracks.
    """

    def __init__(self, calibration: RoomCalibration, config: AutoDetectionConfig | None = None,
                 *, sigma: float = LikelihoodConfig.sigma) -> None:
        if not (np.isfinite(sigma) and sigma > 0):
            raise DetectionError(f'sigma must be a finite number > 0, got {sigma}')
        self.calibration = calibration
        self.config = cfg = config or AutoDetectionConfig()
        self.sigma = float(sigma)
        self.background = BackgroundBank(cfg.background, calibration=calibration)
        self.detector = Detector(calibration, cfg.detector, beside_radius=cfg.relocate_radius)
        self.releaser = Releaser(calibration, cfg.release)
        self.aux: dict[int, TrackAuxiliary] = {}
        self._last_stamp: int | None = None
        self.timings: dict[str, float] = {}
        self.decisions: list[dict] = []    # per frame: what happened to confirmed detections
        # per frame: track id -> floor place (x, y) its reach found it a person at
        self.reach_moves: dict[int, np.ndarray] = {}
        self._first_seen: dict[int, int] = {}  # track id -> stamp of its first update
        self._placed: dict[int, int] = {}  # track id -> stamp of its birth or last move
        # track id -> stamp of its move again (relocate_interval)
        self._moved_again: dict[int, int] = {}
        # released id -> (stamp, floor xy, its appearance model) for reuse_time
        self._released: dict[int, tuple[int, np.ndarray, PersonModel | None]] = {}
        self._lost_ended: list[int] = []  # released ids whose reuse_time passed unreused
        self._shown_since: dict[int, int] = {}  # id -> birth, move, last hidden or exit stamp
        self.duplicate_checks: list[dict] = []  # per frame: the duplicate judge's calls
        self.adaptations: list[dict] = []  # per frame: the appearance adaptation's decisions
        self._adapted: dict[int, int] = {}  # track id -> stamp of its last model adaptation
        self._first_xy: dict[int, np.ndarray] = {}  # track id -> where it was first updated
        self._travelled: set[int] = set()  # tracks that went adaptation.min_travel from it
        self._pending: _Pending | None = None  # what search() needs from the last update()
        self._worker: ThreadPoolExecutor | None = None  # one thread: background, search
        self._foreground: tuple[list[str], Future] | None = None  # start_foreground()'s job
        self._searching: tuple[_Pending, Future] | None = None    # start_search()'s job
        self.side = [n for n, c in calibration.cameras.items() if not is_ceiling(c)]
        # the appearance ratio of two models, calibrated on the tracks (_calibrate)
        self.likeness = AppearanceRatio(cfg.clutter_distance, self.sigma)
        self._sampled: dict[int, int] = {}  # track id -> stamp of its last calibration sample

    def prepare(self) -> None:
        """Do the one-off work of the first frames ahead (the people cue's floor grid), so
        that a live node does not stall at the bootstrap frame."""
        self.background.prepare()

    def bootstrap(self, frames: Mapping[str, Sequence[np.ndarray]]) -> None:
        """Initialise the background models from empty-room frames per camera."""
        self.background.bootstrap(frames)

    def reset(self) -> None:
        """Forget per-track state and unconfirmed candidates (keeps the background)."""
        self.abandon()
        if self._searching is not None:  # its people belong to the time before the reset
            _, job = self._searching
            self._searching = None
            try:
                job.result()
            except Exception:  # noqa: BLE001 - dropped with the rest of the search
                pass
        self.aux.clear()
        self.reach_moves = {}
        self._first_seen.clear()
        self._placed.clear()
        self._moved_again.clear()
        self._released.clear()
        self._lost_ended.clear()
        self._shown_since.clear()
        self._adapted.clear()
        self._first_xy.clear()
        self._travelled.clear()
        self._sampled.clear()
        self.detector.reset()
        self._last_stamp = None
        self._pending = None

    # -- per frame ------------------------------------------------------------------------
    def start_foreground(self, images: Mapping[str, np.ndarray]) -> None:
        """Start the foreground extraction of a frame set (003 §4.2) on the detection's
        worker thread; :meth:`update` of the same frame set joins it.

        The foreground of frame t needs the background model after the (deferred) update of
        frame t-1 and the images, not the tracks of frame t (their silhouettes only keep the
        model update off people, :meth:`BackgroundBank.exclude_pending`), so a tracker starts
        it before its filter step and the two overlap (the numba kernels and OpenCV release
        the GIL); the results are those of extracting it within :meth:`update`. The caller
        must call :meth:`update` (or :meth:`abandon`) before touching the background."""
        self.abandon()
        names = [n for n in images if n in self.calibration.cameras]
        job = self._executor().submit(self.background.apply, {n: images[n] for n in names},
                                      defer=True)
        self._foreground = (names, job)

    def started_foreground(self) -> dict[str, np.ndarray]:
        """The foreground masks of the frame set :meth:`start_foreground` started, waiting
        for them (empty when none was started, a camera is still bootstrapping, or the
        extraction failed: :meth:`update` then reports that failure)."""
        if self._foreground is None:
            return {}
        try:
            return dict(self._foreground[1].result())
        except Exception:  # noqa: BLE001 - update() raises it with its context
            return {}

    def started_possible(self) -> dict[str, np.ndarray | None]:
        """Per camera the (H, W) bool pixels of the frame set whose foreground
        :meth:`start_foreground` started that the background test set to foreground without
        a known background (the bootstrap's possible people,
        ``possible_foreground_as_tested``), None where there are none; waits for that
        foreground like :meth:`started_foreground`."""
        return self._possible(self.started_foreground())

    def _possible(self, foreground: Mapping[str, np.ndarray]) -> dict[str, np.ndarray | None]:
        """Per camera of ``foreground`` its background model's possible foreground as the
        last test used it, None where there is none (or it has another shape)."""
        out: dict[str, np.ndarray | None] = {}
        for name, fg in foreground.items():
            mask = self.background.model(name).possible_foreground_as_tested
            out[name] = mask if mask.shape == fg.shape and mask.any() else None
        return out

    def abandon(self) -> None:
        """Wait for a foreground started by :meth:`start_foreground` whose frame set will not
        be updated (its step failed) and drop its deferred background update."""
        if self._foreground is not None:
            _, job = self._foreground
            self._foreground = None
            try:
                job.result()
            except Exception:  # noqa: BLE001 - the frame set is abandoned anyway
                pass
            self.background.drop_pending()

    def _executor(self) -> ThreadPoolExecutor:
        if self._worker is None:
            self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix='detection')
        return self._worker

    def _take_foreground(self, images: Mapping[str, np.ndarray], names: list[str]
                         ) -> dict[str, np.ndarray]:
        """The foreground masks of the frame set: joined from :meth:`start_foreground`, or
        extracted now (model update deferred)."""
        if self._foreground is not None:
            started, job = self._foreground
            self._foreground = None
            if started != names:
                self._foreground = (started, job)
                self.abandon()
                raise DetectionError(f'update() got cameras {names}, the foreground was '
                                     f'started for {started}')
            return job.result()
        return self.background.apply({n: images[n] for n in names}, defer=True)

    def step(self, stamp_ns: int, images: Mapping[str, np.ndarray],
             tracks: Sequence[TrackEstimate], models: Mapping[int, PersonModel]
             ) -> tuple[list[int], list[Birth]]:
        """Process one frame set after the tracker's filter step: :meth:`update`, then
        :meth:`search`.

        Returns:
            (ids of tracks to release now, people to add).
        """
        ended = self.update(stamp_ns, images, tracks, models)
        return ended, self.search()

    def update(self, stamp_ns: int, images: Mapping[str, np.ndarray],
               tracks: Sequence[TrackEstimate], models: Mapping[int, PersonModel], *,
               bins: Mapping[str, np.ndarray] | None = None) -> list[int]:
        """Background, support, visibility, existence and release for one frame set.

        Fills ``visibility`` and ``existence`` of ``tracks`` in place and keeps what
        :meth:`search` needs. Everything that decides this frame's output happens here; the
        search only adds tracks for the next frame, so a node can publish in between.

        Args:
            stamp_ns: the frame stamp.
            images: camera -> (H, W, 3) uint8 RGB.
            tracks: the tracker's estimates of this frame.
            models: track id -> person model (for shapes and appearance).
            bins: colour bins (``appearance.quantize``) of cameras already quantised this
                frame (the tracker's measurement model), reused.

        Returns:
            ids of the tracks to release now.
        """
        cfg = self.config
        t0 = time.perf_counter()
        self.reach_moves = {}
        self.duplicate_checks = []
        self.adaptations = []
        self._first_seen = {t.track_id: self._first_seen.get(t.track_id, int(stamp_ns))
                            for t in tracks}
        dt = 0.0 if self._last_stamp is None else max(stamp_ns - self._last_stamp, 0) / 1e9
        self._last_stamp = int(stamp_ns)
        names = [n for n in images if n in self.calibration.cameras]
        means = np.array([t.mean for t in tracks]).reshape(-1, 6)
        shapes = [self._shape(models.get(t.track_id), t) for t in tracks]
        # posterior particles for the visibility likelihood (step 3), rasterised in the side
        # cameras together with the tracks (one rasterisation per camera)
        parts, owner, part_shapes = self._visibility_particles(tracks, models, shapes)
        part_sils = {}
        tops = head_heights(means, shapes)
        # 1. rendered tracks per camera
        sils, masks = {}, {}
        for n in names:
            cam = self.calibration.cameras[n]
            sil = None
            if len(tracks):
                k = len(tracks)
                if len(parts) and n in self.side:
                    both = rasterize(cam, np.concatenate([means, parts]), shapes + part_shapes)
                    sil = both.select(0, k)
                    part_sils[n] = both.select(k, k + len(parts))
                else:
                    sil = rasterize(cam, means, shapes)
                sils[n] = sil
            # the update keeps off the tracks (the blob below a top-down camera too; only
            # there: the wider blob everywhere would also shield bootstrap ghosts and screen
            # changes under false tracks, which then live several times longer)
            masks[n] = exclusion_mask(cam, means, shapes, tops, sil)
        t1 = time.perf_counter()
        # 2. background and foreground
        # the model update (and with it the motion the detector needs) waits for search()
        fg = self._take_foreground(images, names)
        self.background.exclude_pending(masks)
        known_bins = dict(bins or {})
        det = self.config.detector
        undecided = self._possible(fg)
        evidence = {n: FrameEvidence(images[n], fg[n], masks[n], undecided.get(n),
                                     _bins=known_bins.get(n),
                                     edge_min_pixels=det.edge_min_pixels,
                                     edge_neighbourhood=det.edge_neighbourhood)
                    for n in fg}
        t2 = time.perf_counter()
        # 3. support, visibility and existence
        ended: list[int] = []
        if tracks:
            coverage = {}
            if evidence:   # its verdict: self.releaser.kept (the coverage is existence's)
                _, coverage = self.releaser.support(evidence, sils, means, tops)

            def colour(name: str) -> np.ndarray | None:
                """Colour bins of a camera this frame, quantised at most once."""
                if name in evidence:
                    return evidence[name].bins
                if name not in images:
                    return None
                if name not in known_bins:
                    known_bins[name] = quantize(images[name])
                return known_bins[name]

            spare = self.releaser.spare if evidence else np.zeros(len(tracks), bool)

            def reach(k: int) -> tuple[np.ndarray, list[dict[str, float]]]:
                """Places (M, 2) of track k's reach and its silhouette's coverages there
                (none for a spare track: the others explain its foreground; none for a
                track younger than ``reach_age``)."""
                age = (int(stamp_ns) - self._first_seen[tracks[k].track_id]) / 1e9
                if (k < len(spare) and spare[k]) or age < cfg.reach_age:
                    return np.zeros((0, 2)), []
                return self._reach_coverage(k, evidence, sils, means, shapes, tops)

            self._auxiliary(dt, colour, tracks, models, parts, owner, part_sils, coverage,
                            reach)
            existence = [self.aux[t.track_id].existence for t in tracks]
            if evidence:  # 4. release (only once the background exists)
                ids = [t.track_id for t in tracks]
                # the existence weighs the coverage evidence (001 §3.2): the release's own
                # verdict is only the spare and doorway rules' (Releaser.kept)
                supported = self.releaser.kept
                ended = self.releaser.exited(ids, means[:, [X, Y]])
                if ended:            # the others go on; the releaser forgets the exited
                    keep = [k for k, i in enumerate(ids) if i not in ended]
                    ended += self.releaser.update(stamp_ns, [ids[k] for k in keep],
                                                  supported[keep],
                                                  [existence[k] for k in keep],
                                                  self.releaser.doorway[keep],
                                                  self.releaser.spare[keep])
                else:
                    ended = self.releaser.update(stamp_ns, ids, supported, existence,
                                                 self.releaser.doorway, self.releaser.spare)
                # of two tracks on one person the one reported without a break for the
                # shorter time goes (born, moved, hidden or inside an exit later): a track
                # that was in an exit may have lost its person there; and not while it
                # keeps exclusive support (two people passing close each explain
                # foreground the other does not)
                shown = [self._shown_since.get(i, 0) for i in ids]
                judge = None if np.isinf(cfg.duplicate_margin) else self._duplicate_judge(
                    tracks, means, models, evidence)
                ended += [i for i in self.releaser.duplicates(
                    stamp_ns, ids, means[:, [X, Y]], shown, judge,
                    self.releaser.exclusive_support)
                    if i not in ended]
        for tid in ended:
            self.aux.pop(tid, None)
            self._placed.pop(tid, None)
            self._moved_again.pop(tid, None)
            self._shown_since.pop(tid, None)
            self._adapted.pop(tid, None)
            self._first_xy.pop(tid, None)
            self._travelled.discard(tid)
            self._sampled.pop(tid, None)
        self._note_reporting(stamp_ns, tracks, means, ended, models)
        t3 = time.perf_counter()
        if cfg.adaptation.rate > 0 and tracks and evidence:
            self._adapt(stamp_ns, tracks, models, means, sils, evidence, ended)
        if tracks and evidence:
            self._calibrate(stamp_ns, images, tracks, models, means, shapes, ended)
        self.timings = {'detect_render': t1 - t0, 'detect_background': t2 - t1,
                        'detect_existence': t3 - t2, 'detect_adapt': time.perf_counter() - t3}
        self._pending = _Pending(int(stamp_ns), images, tracks, models, means, shapes,
                                 evidence, ended)
        return ended

    def search(self) -> list[Birth]:
        """Detection and acquisition (003 §4.1-4.2) on the frame set of the last
        :meth:`update`: the people to add, new or re-found (at most once per update).

        Two parts: :meth:`_find` (background update, detector, acquisition: state of the
        background and the detector only, and the pending frame) and :meth:`_settle` (which
        detection is whose: the tracks' bookkeeping). :meth:`start_search` runs the first on
        the worker thread, :meth:`finish_search` the second."""
        self.update_background()
        if self._pending is None:
            return []
        pending, self._pending = self._pending, None
        return self._settle(pending, self._find(pending))

    def start_search(self, born: Sequence[tuple[np.ndarray, BodyShape]] = ()) -> None:
        """Start the search of the last :meth:`update` on the worker thread (the deferred
        background update, then :meth:`_find`); :meth:`finish_search` settles it.

        ``born``: (state (6,), shape) of people who became tracks after that update (the
        previous search's): excluded from this search like the frame's tracks. Until
        :meth:`finish_search` the caller must not touch the background or the detector;
        :meth:`update` and :meth:`start_foreground` of the next frame may run (the worker
        runs jobs in order, so the next foreground sees the updated background)."""
        if self._pending is None:
            return
        pending, self._pending = self._pending, None
        job = self._executor().submit(self._update_and_find, pending, list(born))
        self._searching = (pending, job)

    def finish_search(self) -> tuple[int | None, list[Birth]]:
        """(stamp of the searched frame set, its people to add) of :meth:`start_search`,
        waiting for it; (None, []) when none was started."""
        if self._searching is None:
            return None, []
        pending, job = self._searching
        self._searching = None
        return pending.stamp_ns, self._settle(pending, job.result())

    def _update_and_find(self, pending: _Pending, born: list) -> _Found:
        """The worker's part of a pipelined search: background update, then :meth:`_find`."""
        spent = self._update_background(pending)
        found = self._find(pending, born)
        found.timings['detect_background_update'] = spent
        return found

    def _find(self, pending: _Pending, born: Sequence[tuple[np.ndarray, BodyShape]] = ()
              ) -> _Found:
        """Detections confirmed on the pending frame set away from its tracks (and from
        ``born``) and their acquired models (003 §4.1-4.2); a detection that cannot be
        acquired goes back to the detector. Reads only the pending frame and changes only
        the detector, so it may run on the worker while the next frame is filtered."""
        t0 = time.perf_counter()
        acquired: list[tuple[Detection, PersonModel]] = []
        ghosts: list[tuple[Detection, float, float]] = []
        if pending.evidence:
            keep = [k for k, t in enumerate(pending.tracks) if t.track_id not in pending.ended]
            others = pending.means[keep]
            other_shapes = [pending.shapes[k] for k in keep]
            if born:
                others = np.concatenate([others, np.array([b[0] for b in born])])
                other_shapes = other_shapes + [b[1] for b in born]
            present = self._initial(pending, others, other_shapes)
            acquired += present
            if present:
                others = np.concatenate([others, np.array([d.state for d, _ in present])])
                other_shapes = other_shapes + [m.shape for _, m in present]
            confirmed = self.detector.step(pending.evidence, track_xy=others[:, [X, Y]],
                                           stamp_ns=pending.stamp_ns, still=True)
            ratio = self.config.background.ghost_edge_ratio
            least = self.detector.config.min_motion
            for det in confirmed:
                # the border test (off with ratio 0: no ghost is dropped, no still one taken)
                g_model, g_frame, masks = self._outline(det, pending.evidence) \
                    if ratio > 0 else (0.0, 0.0, {})
                if masks and g_model > ratio * g_frame:
                    for n, mask in masks.items():   # learnt at the next update
                        self.background.models[n].learn_next(mask)
                    ghosts.append((det, g_model, g_frame))
                    continue
                if det.motion < least and not (masks and g_frame > ratio * g_model):
                    continue    # still, and not shown to be somebody there now
                model = acquire(det, pending.images, self.calibration, others=others,
                                other_shapes=other_shapes, config=self.config.acquisition)
                if model is None:
                    self.detector.requeue(det)
                else:
                    acquired.append((det, model))
        return _Found(acquired, {'detect_find': time.perf_counter() - t0}, tuple(ghosts))

    def _initial(self, pending: _Pending, others: np.ndarray, other_shapes: list
                 ) -> list[tuple[Detection, PersonModel]]:
        """The people present when the background was bootstrapped, initialised together
        on the first frame set with foreground: the people cue's places
        (:meth:`~.background.BootstrapCue.take_places`, found over the bootstrap frames
        from multi-view motion) refined by the detector on this frame
        (:meth:`~.detector.Detector.detect_at`), and each one's appearance model acquired
        with all the others - current tracks ``others`` (K, 6) with ``other_shapes`` and the
        other people present - as occluders (003 §4.1). Confirming them one by one over
        ``confirm_frames`` frames, a few refinements per frame, would leave the last of a
        roomful found a second later. A place the detector does not confirm here is left to
        the ordinary search."""
        cue = getattr(self.background, 'bootstrap_cue', None)
        places = None if cue is None else cue.take_places()
        if places is None or not len(places):
            return []
        dets = self.detector.detect_at(pending.evidence, places, track_xy=others[:, [X, Y]])
        _log.debug('people present at the bootstrap: cue places %s, detections %s',
                   np.round(places, 2).tolist(),
                   [(round(float(d.xy[0]), 2), round(float(d.xy[1]), 2), round(d.score, 2))
                    for d in dets])
        if not dets:
            return []
        states = np.array([d.state for d in dets])
        shapes = [BodyShape(d.height, d.width) for d in dets]
        out = []
        for k, det in enumerate(dets):
            rest = [j for j in range(len(dets)) if j != k]
            model = acquire(det, pending.images, self.calibration,
                            others=np.concatenate([others, states[rest]]),
                            other_shapes=list(other_shapes) + [shapes[j] for j in rest],
                            config=self.config.acquisition)
            if model is not None:
                out.append((det, model))
        return out

    def _outline(self, det: Detection, evidence: Mapping[str, FrameEvidence]
                 ) -> tuple[float, float, dict[str, np.ndarray]]:
        """Whose outline a confirmed detection's foreground has: (model, frame) outline
        gradients summed over the side cameras that judge it, and their silhouette masks
        (H, W) bool (none: no camera judges it).

        The background's border test (:func:`~.background.ghost_components`) applied to
        the foreground of the detection's silhouette (within 4 pixels at 320x240) instead
        of a whole foreground component: the colour gradient along that foreground's
        outline (other tracks' silhouettes left out), in the model and in the frame, in
        each side camera with a background model where at least half of the outline
        counts. ``ghost_edge_ratio`` times larger in the model: a ghost, the outline of
        somebody learnt into the model who has left (the component test misses such a
        ghost when its foreground touches a person standing beside it, whose outline is in
        the frame); that many times larger in the frame: somebody there now, which is the
        proof a detection without recent motion needs (a person who stood still while no
        track followed her); in between the test does not decide."""
        shape = BodyShape(det.height, det.width)
        model_sum = frame_sum = 0.0
        masks = {}
        for n in self.side:
            ev = evidence.get(n)
            bank = self.background.models.get(n)
            if ev is None or bank is None or not bank.ready:
                continue
            cam = self.calibration.cameras[n]
            mask = render_labels(cam, det.state, shape) > 0
            width = max(2, int(round(4.0 * np.sqrt(cam.width * cam.height / 76800.0))))
            g_model, g_frame, share = bank.outline_gradients(ev.image, ev.foreground, mask,
                                                             width=width, exclude=ev.tracks)
            if share >= 0.5:
                model_sum += g_model
                frame_sum += g_frame
                masks[n] = mask
        return model_sum, frame_sum, masks

    def _settle(self, pending: _Pending, found: _Found) -> list[Birth]:
        """Births and moves from the detections of :meth:`_find`, decided jointly
        (:meth:`_associate`); the tracks' bookkeeping is changed here only (main thread)."""
        stamp_ns, _, tracks, models, means, _, evidence, ended = pending
        t0 = time.perf_counter()
        births: list[Birth] = []
        self.decisions = []
        if evidence:
            keep = [k for k, t in enumerate(tracks) if t.track_id not in ended]
            # no birth or move by a detection whose body is wholly inside an exit: its
            # centre deeper than half the body's depth, its width seen from the side
            # (003 §2.1: s(pi/2) = 0.7 of the width); a person in the doorway or beyond
            half_depth = 0.5 * float(width_scale(np.array(0.5 * np.pi)))
            for det, g_model, g_frame in found.ghosts:
                self._decide({'xy': (float(det.xy[0]), float(det.xy[1])),
                              'score': float(det.score), 'action': 'drop (ghost)',
                              'outline': (round(g_model, 1), round(g_frame, 1))})
            inside = [(det, model) for det, model in found.acquired
                      if not self.calibration.exit_depth(det.xy)[0] > half_depth * det.width]
            if inside:
                births = self._associate(inside, tracks, keep, means, models, evidence,
                                         stamp_ns)
        self.timings.update(found.timings)
        self.timings['detect_search'] = found.timings['detect_find'] \
            + time.perf_counter() - t0
        self.timings['detect'] = sum(self.timings.get(k, 0.0) for k in (
            'detect_render', 'detect_background', 'detect_existence', 'detect_adapt',
            'detect_background_update', 'detect_search'))
        return births

    def update_background(self) -> None:
        """The background model update of the last :meth:`update` (003 §4.2), deferred so
        that it does not delay the frame's result, and the recent motion it gives to the
        frame's evidence (the detector's proof that a detection is no ghost). :meth:`search`
        runs it first; the results are those of updating within :meth:`update`."""
        self.timings['detect_background_update'] = self._update_background(self._pending)

    def _update_background(self, pending: _Pending | None) -> float:
        """Run the deferred background update and fill ``pending``'s evidence motion;
        returns the seconds spent."""
        t0 = time.perf_counter()
        self.background.update_pending()
        if pending is not None:
            for name, ev in pending.evidence.items():
                if ev.motion is None:
                    ev.motion = self.background.models[name].presence()
        return time.perf_counter() - t0

    def tracking_images(self, images: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The images the tracking filter should use: the side cameras only (003 §5: the
        top-down view triggers detection and release, tracking uses the corner cameras)."""
        side = {n: im for n, im in images.items() if n in self.side}
        return side or dict(images)

    def register(self, track_id: int, stamp_ns: int | None = None) -> None:
        """Start the auxiliary processes of a new track (born at ``stamp_ns``)."""
        self.aux[int(track_id)] = TrackAuxiliary(self.config.existence)
        if stamp_ns is not None:
            self._placed[int(track_id)] = int(stamp_ns)
            self._shown_since[int(track_id)] = int(stamp_ns)

    def carry(self, tracks: Sequence[TrackEstimate]) -> None:
        """Fill ``visibility`` and ``existence`` of ``tracks`` in place with the values of
        the last :meth:`update` (a frame set the detection skips, ``detection_every``); no
        decision is made on such a frame set."""
        self.decisions = []
        for t in tracks:
            aux = self.aux.get(t.track_id)
            if aux is not None:
                t.visibility = dict(aux.visibility)
                t.existence = float(aux.existence)

    def finished(self, released: Sequence[int]) -> list[int]:
        """The ids that end now, of ``released`` (this frame's :meth:`update`) and of those
        released before: a released track whose person may be re-found (``reuse_time``) is
        only *lost* until its reuse window has passed unused (not reported, like a hidden
        track); it ends then, and an id that is re-used never ends. Ids are thus never
        reused after they ended. With ``reuse_time`` 0 every released id ends at once."""
        done, self._lost_ended = self._lost_ended, []
        return done + [int(t) for t in released if int(t) not in self._released]

    def reported(self, track_id: int) -> bool:
        """Whether the track is reported: its existence is at least the existence
        process's ``report_threshold`` (001 §3.2; a track without one yet is)."""
        aux = self.aux.get(int(track_id))
        return aux is None or aux.reported

    # -- helpers --------------------------------------------------------------------------
    def _adapt(self, stamp_ns: int, tracks: Sequence[TrackEstimate],
               models: Mapping[int, PersonModel], means: np.ndarray,
               sils: Mapping[str, object], evidence: Mapping[str, FrameEvidence],
               ended: Sequence[int]) -> None:
        """Appearance adaptation (:func:`adaptation.adapt_models`) of the tracks that stay
        reported with high existence and were not born or moved within
        ``relocate_interval`` (a young or just-moved track may sit on the wrong person),
        each at most once per ``adaptation.interval``, and only once it has been
        ``adaptation.min_travel`` from where it was first seen."""
        cfg = self.config.adaptation
        ids = [t.track_id for t in tracks]
        for k, tid in enumerate(ids):
            if tid in ended:
                continue
            start = self._first_xy.setdefault(tid, means[k, [X, Y]].copy())
            if np.hypot(*(means[k, [X, Y]] - start)) >= cfg.min_travel:
                self._travelled.add(tid)
        due = int(cfg.interval * 1e9)
        eligible = np.array([
            tid not in ended and tid in self.aux and self.reported(tid)
            and self.aux[tid].existence >= cfg.min_existence
            and not self._placed_recently(tid, stamp_ns) and tid in self._travelled
            and int(stamp_ns) - self._adapted.get(tid, int(stamp_ns) - due) >= due
            for tid in ids])
        if not eligible.any():
            return
        side = [n for n in self.side if n in evidence and n in sils]
        self.adaptations = adapt_models(
            cfg, self.calibration, {n: evidence[n].bins for n in side},
            {n: sils[n] for n in side}, means, ids, [models.get(tid) for tid in ids],
            eligible, [self.aux[tid].visibility if tid in self.aux else {} for tid in ids],
            {n: evidence[n].foreground for n in side})
        for r in self.adaptations:
            if r['action'] != 'inconsistent':
                self._adapted[r['id']] = int(stamp_ns)

    def _calibrate(self, stamp_ns: int, images: Mapping[str, np.ndarray],
                   tracks: Sequence[TrackEstimate], models: Mapping[int, PersonModel],
                   means: np.ndarray, shapes: Sequence[BodyShape], ended: Sequence[int]
                   ) -> None:
        """Samples for the appearance ratio (:class:`.likeness.AppearanceRatio`) from the
        tracks followed confidently: reported, existence at least the adaptation's
        ``min_existence`` (001 §3.2), not born or moved within ``relocate_interval``. The
        association weighs a track's person against somebody else within its gate, so
        the samples are taken where that question arises: of a confident track with
        another within ``reuse_radius`` (metres), at most once per
        :data:`CALIBRATION_INTERVAL`, a model is acquired at its estimate (003 §4.1, the
        other tracks as occluders), as a detection's would be; that model's distance
        (003 Eq. 4) to the track's own model is a "same person" sample, its distances to
        the models of the confident tracks within ``reuse_radius`` (other people: two
        tracks at once) are "different people" samples."""
        ids = [t.track_id for t in tracks]
        least = self.config.adaptation.min_existence
        sure = [k for k, tid in enumerate(ids)
                if tid not in ended and tid in self.aux and self.reported(tid)
                and self.aux[tid].existence >= least
                and not self._placed_recently(tid, stamp_ns)
                and models.get(tid) is not None and models[tid].view_angles.size]
        xy = means[sure][:, [X, Y]]
        gate = np.hypot(*(xy[:, None] - xy[None]).T) <= self.config.reuse_radius
        np.fill_diagonal(gate, False)
        due = int(CALIBRATION_INTERVAL * 1e9)
        for i, k in enumerate(sure):
            tid = ids[k]
            near = [sure[j] for j in np.flatnonzero(gate[i])]
            if not near or (tid in self._sampled
                            and int(stamp_ns) - self._sampled[tid] < due):
                continue
            self._sampled[tid] = int(stamp_ns)
            rest = [j for j in range(len(tracks)) if j != k and ids[j] not in ended]
            shape = models[tid].shape
            seen = Detection(state=means[k].copy(), height=shape.height, width=shape.width,
                             score=0.0)
            fresh = acquire(seen, images, self.calibration, others=means[rest],
                            other_shapes=[shapes[j] for j in rest],
                            config=self.config.acquisition)
            if fresh is None:
                continue
            self.likeness.add(same=model_distance(models[tid], fresh),
                              different=[model_distance(models[ids[j]], fresh)
                                         for j in near])
            if _log.isEnabledFor(logging.DEBUG):
                _log.debug('appearance calibration after track %d: %s', tid,
                           self.likeness.describe())
