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
"""
from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from mbtrack_ros.core import _kernels
from mbtrack_ros.core.appearance import (
    PersonModel, key_view_loglik, key_view_stack, model_distance, quantize, relative_angle,
    single_target_loglik, view_weights)
from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.core.detection import DetectionError
from mbtrack_ros.core.detection.acquisition import AcquisitionConfig, acquire
from mbtrack_ros.core.detection.adaptation import AdaptationConfig, adapt_models
from mbtrack_ros.core.detection.background import BackgroundBank, BackgroundConfig
from mbtrack_ros.core.detection.detector import (
    Detection, Detector, DetectorConfig, FrameEvidence, is_ceiling)
from mbtrack_ros.core.detection.features import span_counts
from mbtrack_ros.core.detection.release import (
    ReleaseConfig, Releaser, blob_coverage, paint_blobs, spare_tracks,
)
from mbtrack_ros.core.existence import (
    AuxiliaryConfig, TrackAuxiliary, coverage_log_ratio, predictive_loglik,
)
from mbtrack_ros.core.resampling import systematic_indices
from mbtrack_ros.core.shape import BodyShape, rasterize
from mbtrack_ros.core.state import SIT, THETA, VX, VY, X, Y, TrackEstimate

__all__ = ['AutoDetection', 'AutoDetectionConfig', 'Birth']

_log = logging.getLogger(__name__)

_MID = np.array([0.5])     # offset of the systematic selection of visibility particles


@dataclass(frozen=True)
class AutoDetectionConfig:
    """All parameters of the automatic detection pipeline.

    Units: metres, seconds, nats (natural-log likelihood ratios) per side camera,
    appearance distances in [0, 1] (``appearance.model_distance``), supports and coverages
    as foreground fractions in [0, 1].

    Attributes:
        background, detector, release, acquisition, existence: per-stage parameters.
        adaptation: the slow appearance-model adaptation of confirmed tracks
            (:mod:`~mbtrack_ros.core.detection.adaptation`; ``rate`` 0 is off).
        sigma: appearance likelihood width (003 Eq. 3), as the tracker's.
        clutter_distance: Bhattacharyya distance whose likelihood is the "not visible"
            clutter likelihood ``p_0`` (001 Eq. 23).
        visibility_particles: posterior particles used per track for ``p_1`` (001 Eq. 18).
        side_weight: weight in [0, 1] of the side cameras' evidence in the existence update
            when a top-down camera exists.
        report_hidden: also report tracks whose existence is below the report threshold.
        relocate_radius: metres; a confirmed detection this close to a current track is
            compared with the track's appearance model before it may start a new track.
        relocate_margin: nats per side camera; mean log-likelihood gain (003 Eq. 3 under
            the track's model) of the detection over the track's estimate above which the
            detection is the track's own person and the track is moved there instead of a
            birth (:meth:`AutoDetection._identify`); negative means "about as well".
            Lower moves tracks more readily (fewer duplicate births, more moves onto
            another person).
        weak_relocate_margin: nats per side camera; the same margin for a detection scoring
            below ``beside_threshold`` (the larger of the two applies; ``inf``: such a
            detection moves no track by the gain). Weak detections beside a track are often
            a neighbour's fringe, so they need a clear gain.
        move_support: a track is moved by the gain only while the detection would leave it
            spare: its exclusive support (:func:`~.release.spare_tracks`) with the
            detection as one more track must be below this fraction. A track that keeps
            foreground of its own beside the detection stands on a person of its own and
            the detection is somebody else. Above 1: no track is kept from a move.
        move_distance: appearance distance; a detection the gain would move a track to
            although the track's model explains it worse than the track's own estimate
            (gain in ``(relocate_margin, 0]``) must look like the track: distance at most
            this. 1 lets the gain alone decide.
        look_alike_slack: nats per side camera below ``relocate_margin`` down to which the
            gain may still move a look-alike track (distance at most ``move_distance``)
            for a strong detection (``beside_threshold``) that would leave the track less
            than ``move_support``; 0 is off. Catches tracks left behind where their person
            turned.
        relocate_interval: seconds after a track was born or moved during which a detection
            does not move it again but is dropped (a young model explains several people
            in a group about equally well: the track would hop between them).
        move_again_gain: nats per side camera; within ``relocate_interval`` a detection
            whose gain for that track is above this moves it again (once) instead of
            being dropped. ``inf``: always dropped.
        relocate_hidden: a confirmed detection that would start a new track within
            ``relocate_radius`` of a track that is not reported (existence below the report
            threshold: it lost its person) moves that track instead, whatever the gain
            (the nearest such track not placed within ``relocate_interval``).
        reuse_time, reuse_radius: seconds, metres; a released track is *lost* for
            ``reuse_time``: a new track born within ``reuse_radius`` of where it was
            released takes its id (its person re-found) when the two look alike
            (``reuse_distance``). The id ends (:meth:`finished`) only when that time has
            passed unused, so an id never comes back after it ended. 0 ends released tracks
            at once. The time should cover a person standing still after being lost (a few
            seconds); the radius how far a lost track may lag its person.
        reuse_distance: largest appearance distance between a released track's model and a
            detection's for the detection to take the released id; 1 accepts any.
        reuse_in_entry_zones: a track released inside an entry zone is lost for
            ``reuse_time`` like any other; False: its id ends at once (its person is taken
            to have left the room).
        reuse_before_moving: before a detection moves a track (by the gain or as a hidden
            track), a lost track within ``reuse_radius`` whose model is nearer the
            detection's than the moved track's model takes its id back instead, and the
            track stays where it is. Not when that track was placed within
            ``relocate_interval`` (its move would not happen).
        reuse_hidden: a detection that would start a new track moves instead the nearest
            hidden track (not reported, not placed within ``relocate_interval``) within
            ``reuse_radius`` whose model is within ``reuse_distance`` of the detection's:
            a hidden track is given back its person like a lost one.
        reuse_doubtful: existence probability below which a reported track counts as hidden
            for ``reuse_hidden`` (logged "move N (doubtful, far)"); 0 disables. With
            ``report_hidden`` every hidden track is reported, so this level is what lets
            ``reuse_hidden`` take them.
        duplicate_by_reporting: of two tracks on one person (release ``merge_radius``,
            ``merge_time``) release the one reported without a break for the shorter time
            (born, moved, hidden or inside an exit later) instead of the younger one: a
            track that was in an exit may have lost its person there.
        duplicate_margin: nats per side camera; of two such tracks keep the one whose
            appearance model explains the image where they are better (003 Eq. 3, both
            models at the pair's midpoint) by more than this
            (:meth:`AutoDetection._duplicate_judge`); ``inf`` disables. Large enough that
            a model acquired moments ago (which fits its own view best) does not win alone.
        duplicate_own_support: of such a pair, the track to be released is kept while its
            exclusive support (:meth:`Releaser.exclusive_support`) is at least the
            release's ``spare_support``: two people passing close each explain foreground
            the other does not.
        reach_radius, reach_directions: metres, count; a track whose coverage evidence for
            existence is negative at its mean is also judged at ``reach_directions``
            places on each of two rings around it (radius half and all of
            ``reach_radius``), on the foreground no other track's silhouette covers, and
            the best place counts: a track that fell behind a person who started walking
            stays reported while the person is within the detector's ``exclusion_radius``
            (where the detector does not look for them); 0 disables.
        reach_move: a track whose reach counted a place with positive coverage evidence
            is also restarted there (same id and velocity, :attr:`AutoDetection.reach_moves`;
            the tracker moves it after the frame's output), so that it catches up with its
            person instead of staying behind.
        catch_up: nats; a track older than ``reach_age`` whose coverage evidence at its
            mean is not negative is still restarted at the best place of its reach when the
            free foreground there gives coverage evidence higher by more than this than at
            its mean (a track left behind a person keeps part of their foreground). Not
            where the reach touches an entry zone (a newcomer's foreground is there).
            ``inf`` disables (the default).
        reach_age: seconds a track must have existed before it has a reach: a false birth
            (a shadow, a ghost, the fringe of a person) would keep itself alive on what is
            near it; false births mostly die within a few seconds.
        exit_rescue: coverage fraction; a track that the exit rule would release is instead
            moved onto the floor, same id, when a place within ``reach_radius`` of its
            estimate brought onto the floor shows a free person with mean coverage at least
            this in the cameras that watch the place (the doorway witnesses, elsewhere the
            corner cameras). At most once per ``relocate_interval`` per track. 0 disables
            (the default).
        beside_support: a confirmed detection that would start a new track next to a
            reported track (within ``beside_radius``, not spare, not moved within
            ``relocate_interval``) moves that track there instead (same id) when, with the
            detection as one more track, the track's exclusive support falls below this
            fraction from above: the track had fallen behind the detection's person and
            lived on their fringe (:meth:`AutoDetection._lagging_beside`); 0 disables (the
            default).
        beside_radius: metres; the track ``beside_support`` moves must be this close to
            the detection.
        beside_threshold: smallest detection score (the detector's combined log response)
            for a birth within ``relocate_radius`` of a track that the detection did not
            move: weak detections beside a track are mostly the fringe of that track's
            person or a gap between people; 0 keeps the detector's threshold alone.
        young_look_alike: a confirmed detection that would start a new track within
            ``relocate_radius`` of a track placed within ``relocate_interval`` whose model
            looks like the detection's (``move_distance``) is dropped: a young track lags
            its person for a few frames, and the detection beside it is that person.
        track_coverage: ``k`` of a foreground-coverage term ``k f_c`` per camera in the
            tracking filter's particle weights (:meth:`MeasurementModel.set_foreground`);
            0: colour alone. Larger holds tracks on the foreground more firmly (better
            MOTP, fewer switches) at the cost of the colour evidence's say.
        birth_exit_depth: metres; a confirmed detection deeper than this inside an exit
            starts or moves no track (its person is in the doorway or beyond).
    """

    background: BackgroundConfig = field(default_factory=BackgroundConfig)
    detector: DetectorConfig = field(default_factory=DetectorConfig)
    release: ReleaseConfig = field(default_factory=ReleaseConfig)
    acquisition: AcquisitionConfig = field(default_factory=AcquisitionConfig)
    existence: AuxiliaryConfig = field(default_factory=AuxiliaryConfig)
    adaptation: AdaptationConfig = field(default_factory=AdaptationConfig)
    sigma: float = 0.12
    clutter_distance: float = 0.5
    visibility_particles: int = 6
    side_weight: float = 0.3
    report_hidden: bool = False
    relocate_radius: float = 1.0
    relocate_margin: float = -3.0
    weak_relocate_margin: float = 1.5
    move_support: float = 0.3
    move_distance: float = 0.65
    look_alike_slack: float = 3.0
    relocate_interval: float = 2.0
    move_again_gain: float = 0.0
    relocate_hidden: bool = True
    reuse_time: float = 3.0
    reuse_radius: float = 1.5
    reuse_distance: float = 0.55
    reuse_in_entry_zones: bool = True
    reuse_before_moving: bool = True
    reuse_hidden: bool = True
    reuse_doubtful: float = 0.9
    duplicate_by_reporting: bool = True
    duplicate_margin: float = 8.0
    duplicate_own_support: bool = True
    reach_radius: float = 0.5
    reach_directions: int = 8
    reach_move: bool = True
    reach_age: float = 4.0
    catch_up: float = float('inf')
    exit_rescue: float = 0.0
    beside_support: float = 0.0
    beside_radius: float = 0.6
    beside_threshold: float = 3.0
    young_look_alike: bool = True
    birth_exit_depth: float = 0.15
    track_coverage: float = 2.0

    def looks_alike(self, unlike: float) -> bool:
        """Whether a track whose model is ``unlike`` (appearance distance) from a
        detection's looks like it (``move_distance``)."""
        return unlike <= self.move_distance

    def gain_gate(self, score: float, gain: float, unlike: float) -> str | None:
        """Whether the appearance gain (003 Eq. 3, nats per side camera) lets a detection
        of ``score`` move a track whose model is ``unlike`` (appearance distance) from the
        detection's: 'move'; 'unlike' when the gain is in the doubtful band (margin, 0]
        and the track does not look like the detection (``move_distance`` keeps it back);
        None when the gain is too low. The margin is ``relocate_margin``, the stricter
        ``weak_relocate_margin`` below ``beside_threshold``; a strong detection may move
        a look-alike ``look_alike_slack`` below it (:meth:`AutoDetection._identify`)."""
        strong = score >= self.beside_threshold
        margin = self.relocate_margin if strong \
            else max(self.relocate_margin, self.weak_relocate_margin)
        alike_margin = self.relocate_margin - self.look_alike_slack if strong else margin
        looks_alike = self.looks_alike(unlike)
        if margin < gain <= 0.0 and not looks_alike:
            return 'unlike'
        return 'move' if gain > margin or (looks_alike and gain > alike_margin) else None

    def __post_init__(self) -> None:
        if not self.relocate_radius >= 0 or not np.isfinite(self.relocate_margin):
            raise DetectionError('relocate_radius must be >= 0 and relocate_margin finite')
        if np.isnan(self.weak_relocate_margin) or self.weak_relocate_margin == -np.inf:
            raise DetectionError(f'weak_relocate_margin must be a number or inf, got '
                                 f'{self.weak_relocate_margin}')
        if np.isnan(self.move_again_gain) or self.move_again_gain == -np.inf:
            raise DetectionError(f'move_again_gain must be a number or inf, got '
                                 f'{self.move_again_gain}')
        if not (np.isfinite(self.look_alike_slack) and self.look_alike_slack >= 0):
            raise DetectionError(f'look_alike_slack must be a finite number >= 0, got '
                                 f'{self.look_alike_slack}')
        if not 0.0 <= self.move_distance <= 1.0:
            raise DetectionError(f'move_distance must be in [0, 1], got {self.move_distance}')
        if not self.move_support >= 0:
            raise DetectionError(f'move_support must be >= 0, got {self.move_support}')
        if not self.duplicate_margin >= 0:
            raise DetectionError(f'duplicate_margin must be >= 0, got {self.duplicate_margin}')
        if not (self.reuse_time >= 0 and self.reuse_radius >= 0
                and 0 <= self.reuse_distance <= 1):
            raise DetectionError('reuse_time and reuse_radius must be >= 0, reuse_distance '
                                 'in [0, 1]')
        if not 0.0 <= self.reuse_doubtful <= 1.0:
            raise DetectionError(f'reuse_doubtful must be in [0, 1], got {self.reuse_doubtful}')
        if not self.sigma > 0 or not self.clutter_distance > 0:
            raise DetectionError('sigma and clutter_distance must be > 0')
        if not self.beside_support >= 0:
            raise DetectionError('beside_support must be >= 0')
        if not (np.isfinite(self.track_coverage) and self.track_coverage >= 0):
            raise DetectionError(f'track_coverage must be a finite number >= 0, got '
                                 f'{self.track_coverage}')
        if not self.beside_radius >= 0:
            raise DetectionError(f'beside_radius must be >= 0, got {self.beside_radius}')
        if not (np.isfinite(self.beside_threshold) and self.beside_threshold >= 0):
            raise DetectionError(f'beside_threshold must be a finite number >= 0, got '
                                 f'{self.beside_threshold}')
        if self.visibility_particles < 1:
            raise DetectionError('visibility_particles must be >= 1')
        if not (self.catch_up >= 0):
            raise DetectionError(f'catch_up must be >= 0 (inf: off), got {self.catch_up}')
        if not (self.reach_radius >= 0 and self.reach_directions >= 1
                and self.reach_age >= 0):
            raise DetectionError('reach_radius and reach_age must be >= 0 and '
                                 'reach_directions >= 1')
        if not 0.0 <= self.exit_rescue <= 1.0:
            raise DetectionError(f'exit_rescue must be in [0, 1], got {self.exit_rescue}')
        if not (np.isfinite(self.birth_exit_depth) and self.birth_exit_depth >= 0):
            raise DetectionError(f'birth_exit_depth must be a finite number >= 0, got '
                                 f'{self.birth_exit_depth}')


@dataclass
class Birth:
    """A new person to add to the tracker, or (``track_id`` set) a current track that
    drifted off its person and must be restarted at the detection, keeping its id."""

    model: PersonModel
    state: np.ndarray
    detection: Detection
    track_id: int | None = None


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


class AutoDetection:
    """Per-frame background, detection, acquisition, release and existence bookkeeping.

    Args:
        calibration: the room.
        config: pipeline parameters.

    The pipeline draws no random numbers: it is deterministic given the tracks.
    """

    def __init__(self, calibration: RoomCalibration, config: AutoDetectionConfig | None = None
                 ) -> None:
        self.calibration = calibration
        self.config = cfg = config or AutoDetectionConfig()
        self.background = BackgroundBank(cfg.background, calibration=calibration)
        self.detector = Detector(calibration, cfg.detector)
        self.releaser = Releaser(calibration, cfg.release)
        self.aux: dict[int, TrackAuxiliary] = {}
        self._last_stamp: int | None = None
        self.timings: dict[str, float] = {}
        self.decisions: list[dict] = []    # per frame: what happened to confirmed detections
        # per frame: track id -> floor place (x, y) its reach found it a person at
        self.reach_moves: dict[int, np.ndarray] = {}
        self.catch_ups: list[dict] = []  # per frame: the reach moves made by catch_up
        self._first_seen: dict[int, int] = {}  # track id -> stamp of its first update
        self._placed: dict[int, int] = {}  # track id -> stamp of its birth or last move
        self._moved_again: dict[int, int] = {}  # track id -> stamp of its move_again_gain move
        # released id -> (stamp, floor xy, its appearance model) for reuse_time
        self._released: dict[int, tuple[int, np.ndarray, PersonModel | None]] = {}
        self._lost_ended: list[int] = []  # released ids whose reuse_time passed unreused
        self._shown_since: dict[int, int] = {}  # id -> birth, move, last hidden or exit stamp
        self._rescued: dict[int, int] = {}  # id -> stamp of its last exit rescue
        self.exit_checks: list[dict] = []  # per frame: the exit rescue's view of each exit
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
        self.ceiling = [n for n in calibration.cameras if n not in self.side]

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
        self.catch_ups = []
        self._first_seen.clear()
        self._placed.clear()
        self._moved_again.clear()
        self._released.clear()
        self._lost_ended.clear()
        self._shown_since.clear()
        self._rescued.clear()
        self._adapted.clear()
        self._first_xy.clear()
        self._travelled.clear()
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
        self.catch_ups = []
        self.exit_checks = []
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
        # head height: sitting keeps the upper body above the chair (003 §2.1)
        tops = np.array([sh.chair_height + (1.0 - sh.hip_fraction) * sh.height
                         if m[SIT] >= 0.5 else sh.height for sh, m in zip(shapes, means)])
        # 1. rendered tracks per camera
        sils, masks = {}, {}
        for n in names:
            cam = self.calibration.cameras[n]
            mask = np.zeros((cam.height, cam.width), bool)
            if len(tracks):
                k = len(tracks)
                if len(parts) and n in self.side:
                    both = rasterize(cam, np.concatenate([means, parts]), shapes + part_shapes)
                    sil = both.select(0, k)
                    part_sils[n] = both.select(k, k + len(parts))
                else:
                    sil = rasterize(cam, means, shapes)
                sils[n] = sil
                paint = mask.view(np.uint8)
                _kernels.paint_spans(paint, sil.row, sil.x0, sil.x1, sil.part, 0,
                                     int(sil.offsets[-1]), 1, False)
                if is_ceiling(cam):
                    # the outline degenerates to a line right below a top-down camera: the
                    # model update must not learn a person standing there (the release
                    # reads this camera's blob, 003 §4.3). Only there: the wider blob
                    # everywhere would also shield bootstrap ghosts and screen changes under
                    # false tracks, which then live several times longer
                    paint_blobs(mask, cam, means[:, :2], tops, outline_area=sil.area)
            masks[n] = mask
        t1 = time.perf_counter()
        # 2. background and foreground
        # the model update (and with it the motion the detector needs) waits for search()
        fg = self._take_foreground(images, names)
        self.background.exclude_pending(masks)
        known_bins = dict(bins or {})
        det = self.config.detector
        evidence = {n: FrameEvidence(images[n], fg[n], masks[n], _bins=known_bins.get(n),
                                     edge_min_pixels=det.edge_min_pixels,
                                     edge_neighbourhood=det.edge_neighbourhood,
                                     ghost=self.background.model(n).possible_foreground_as_tested
                                     if cfg.beside_support > 0 else None)
                    for n in fg}
        t2 = time.perf_counter()
        # 3. support, visibility and existence
        ended: list[int] = []
        if tracks:
            if evidence:
                supported, coverage = self.releaser.support(evidence, sils, means, tops)
            else:
                supported = np.ones(len(tracks), bool)
                coverage = {}

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

            def reach(k: int, centre: bool = False
                      ) -> tuple[np.ndarray, list[dict[str, float]]]:
                """Places (M, 2) of track k's reach and its silhouette's coverages there
                (none for a spare track: the others explain its foreground; none for a
                track younger than ``reach_age``); ``centre``: the mean first."""
                age = (int(stamp_ns) - self._first_seen[tracks[k].track_id]) / 1e9
                if (k < len(spare) and spare[k]) or age < cfg.reach_age:
                    return np.zeros((0, 2)), []
                return self._reach_coverage(k, evidence, sils, means, shapes, tops,
                                            centre=centre)

            self._auxiliary(dt, colour, tracks, models, parts, owner, part_sils, coverage,
                            reach)
            existence = [self.aux[t.track_id].existence for t in tracks]
            if evidence:  # 4. release (only once the background exists)
                ids = [t.track_id for t in tracks]
                ended = self.releaser.exited(ids, means[:, [X, Y]])
                if ended and cfg.exit_rescue > 0:
                    ended = self._rescue_exits(stamp_ns, tracks, ended, evidence, sils,
                                               means, shapes, tops)
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
                shown = [self._shown_since.get(i, 0) if cfg.duplicate_by_reporting else 0
                         for i in ids]
                judge = None if np.isinf(cfg.duplicate_margin) else self._duplicate_judge(
                    tracks, means, models, evidence)
                ended += [i for i in self.releaser.duplicates(
                    stamp_ns, ids, means[:, [X, Y]], shown, judge,
                    self.releaser.exclusive_support if cfg.duplicate_own_support else None)
                    if i not in ended]
        for tid in ended:
            self.aux.pop(tid, None)
            self._placed.pop(tid, None)
            self._moved_again.pop(tid, None)
            self._shown_since.pop(tid, None)
            self._rescued.pop(tid, None)
            self._adapted.pop(tid, None)
            self._first_xy.pop(tid, None)
            self._travelled.discard(tid)
        self._note_reporting(stamp_ns, tracks, means, ended, models)
        t3 = time.perf_counter()
        if cfg.adaptation.rate > 0 and tracks and evidence:
            self._adapt(stamp_ns, tracks, models, means, sils, evidence, ended)
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
        if pending.evidence:
            keep = [k for k, t in enumerate(pending.tracks) if t.track_id not in pending.ended]
            others = pending.means[keep]
            other_shapes = [pending.shapes[k] for k in keep]
            if born:
                others = np.concatenate([others, np.array([b[0] for b in born])])
                other_shapes = other_shapes + [b[1] for b in born]
            confirmed = self.detector.step(pending.evidence, track_xy=others[:, [X, Y]],
                                           stamp_ns=pending.stamp_ns)
            for det in confirmed:
                model = acquire(det, pending.images, self.calibration, others=others,
                                other_shapes=other_shapes, config=self.config.acquisition)
                if model is None:
                    self.detector.requeue(det)
                else:
                    acquired.append((det, model))
        return _Found(acquired, {'detect_find': time.perf_counter() - t0})

    def _settle(self, pending: _Pending, found: _Found) -> list[Birth]:
        """Births and moves from the detections of :meth:`_find` (:meth:`_identify`), in
        the order found; the tracks' bookkeeping is changed here only (main thread)."""
        stamp_ns, _, tracks, models, means, _, evidence, ended = pending
        t0 = time.perf_counter()
        births: list[Birth] = []
        self.decisions = []
        if evidence:
            keep = [k for k, t in enumerate(tracks) if t.track_id not in ended]
            moved: set[int] = set()
            # no birth or move deep in an exit: a person in the doorway or beyond
            limit = self.config.birth_exit_depth
            for det, model in found.acquired:
                if self.calibration.exit_depth(det.xy)[0] > limit:
                    continue
                birth = self._identify(det, model, tracks, keep, means, models, evidence,
                                       moved, stamp_ns)
                if birth is not None:
                    births.append(birth)
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
        aux = self.aux.get(int(track_id))
        return aux is None or aux.reported or self.config.report_hidden

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

    def _identify(self, det: Detection, model: PersonModel, tracks: Sequence[TrackEstimate],
                  keep: Sequence[int], means: np.ndarray, models: Mapping[int, PersonModel],
                  evidence: Mapping[str, FrameEvidence], moved: set[int], stamp_ns: int
                  ) -> Birth | None:
        """A new person, or a current track that drifted off its person, re-found.

        003 §4.1 excludes the neighbourhood of each track from the search, but a track that
        lags or drifted 0.4-0.8 m off its person leaves the person outside that radius:
        the detection would start a second track on the same person (an identity switch
        when the old one is released). So a confirmed detection within ``relocate_radius``
        of a track is first checked with the track's own appearance model (003 Eq. 3, the
        tracker's likelihood): when, on average over the side cameras that see both, the
        model explains the detection about as well as or better than the track's current
        estimate (``log p(y_c | detection) - log p(y_c | track) > relocate_margin``), the
        detection is taken for that track's person and the track is moved there (same id)
        - or, within ``relocate_interval`` of the track's birth or last move, the detection
        is dropped (unless its gain is above ``move_again_gain``: it is moved again, once);
        otherwise a new track is born. A track the detection would leave
        ``move_support`` or more of its exclusive support (foreground no other track
        covers) is not moved: it stands on a person of its own. The gain is a weak cue in
        groups (right and wrong moves both have gains of a few nats either way per camera);
        still, moving instead of a birth avoids most second tracks on one person, and the
        interval stops a track hopping through a
        group. A gain in ``(relocate_margin, 0]`` moves only a track that looks like the
        detection (``move_distance``), and such a look-alike may be moved by a gain down to
        ``look_alike_slack`` below the margin. Of several tracks the gain would move, the
        one whose model is nearest the detection's in appearance is. A detection scoring
        below ``beside_threshold`` needs the stricter ``weak_relocate_margin`` to move a
        track (about half of such moves with a small
        gain went to another person), and when no track takes it and it has a track
        within ``relocate_radius`` it is not born either: weak detections there are mostly
        the fringe of that track's person or a gap between people. Before a track is
        moved (by the gain or hidden), a lost track whose model is nearer the detection's
        takes its id back instead (``reuse_before_moving``); before a birth, a released
        track and then a hidden one within ``reuse_radius`` that look alike are given
        back their person (``reuse_time``, ``reuse_hidden``; a reported track of doubtful
        existence counts as hidden, ``reuse_doubtful``); a detection that would still
        be born beside a look-alike track born or moved within ``relocate_interval`` is
        dropped (``young_look_alike``).
        """
        cfg = self.config
        state = det.state.copy()
        info = {'xy': (float(det.xy[0]), float(det.xy[1])), 'score': float(det.score),
                'v': (round(float(det.state[VX]), 2), round(float(det.state[VY]), 2))}
        near = []                   # (id, distance, gain, appearance distance) of the
        #                             tracks the check compared
        movable = []                # indices of the tracks the gain would move
        unalike = []                # (id, distance) of those move_distance kept back
        likeness = {}               # id -> appearance distance to the detection, once each
        gains = {}                  # id -> appearance gain (nats per side camera), unrounded
        for k in keep:
            tid = tracks[k].track_id
            d = float(np.hypot(*(means[k, [X, Y]] - det.xy)))
            ref = models.get(tid)
            if d > cfg.relocate_radius or ref is None or tid in moved \
                    or not ref.view_angles.size:
                continue
            gain = gains[tid] = self._explains(ref, means[k], state, evidence)
            unlike = likeness[tid] = model_distance(ref, model)
            near.append((int(tid), round(d, 2), round(gain, 3), round(unlike, 3)))
            gate = cfg.gain_gate(det.score, gain, unlike)
            if gate == 'unlike':
                unalike.append((int(tid), round(unlike, 3)))
            elif gate == 'move':
                movable.append(k)
        if near:
            info['near'] = near
        if unalike:
            info['unalike'] = unalike
        support = None              # _exclusive_support, computed once per detection
        if movable:
            # exclusive support with the detection as one more track: a track that keeps
            # move_support of it stands on a person of its own, the detection is another
            support = self._exclusive_support(det, model, tracks, keep, means, models,
                                              evidence)
            with_det = support[1]
            left = {k: float(with_det[j]) for j, k in enumerate(keep)}
            info['support'] = [(int(tracks[k].track_id), round(left[k], 3)) for k in movable]
            movable = [k for k in movable if not left[k] >= cfg.move_support]
        # of several movable tracks, the one whose model is nearest the detection's: each
        # gain is measured against that track's own place (a track drifted off its person
        # gains most), the appearance distance against one reference for all
        best = min(((k, likeness[tracks[k].track_id]) for k in movable),
                   key=lambda kd: kd[1], default=None)
        hidden = False
        if best is None and cfg.relocate_hidden:
            best = self._nearest_hidden(det, tracks, keep, means, models, moved, stamp_ns)
            hidden = best is not None
        if best is not None and cfg.reuse_before_moving \
                and not self._placed_recently(tracks[best[0]].track_id, stamp_ns):
            # a lost track that looks more like the detection than the track about to be
            # moved takes its id back; that track stays where it is. Not instead of a
            # track placed within relocate_interval: that move would not happen (the
            # detection is dropped below), a young track lags its own person
            tid = tracks[best[0]].track_id
            unlike = likeness.get(tid)
            if unlike is None:          # a hidden track the gain check did not compare
                unlike = likeness[tid] = model_distance(models[tid], model)
            info['unlike'] = (int(tid), round(unlike, 3))
            reused = self._reusable(det, model, models, info, below=unlike)
            if reused is not None:
                info['action'] = f'reuse {reused} (not {tid})'
                self._decide(info)
                return Birth(model=model, state=state, detection=det, track_id=reused)
        beside = False
        if best is None and cfg.beside_support > 0:
            best = self._lagging_beside(det, model, tracks, keep, means, models, evidence,
                                        moved, stamp_ns, info, support)
            beside = best is not None
        if best is None and near and det.score < cfg.beside_threshold:
            info['action'] = 'drop (weak beside a track)'
            self._decide(info)
            return None
        far = doubtful = False
        if best is None:
            reused = self._reusable(det, model, models, info)
            if reused is None and cfg.reuse_hidden:
                # a hidden track within reuse_radius that looks like the detection is
                # given back its person like a lost one; so is one reported with a
                # doubtful existence (shown again moments ago, or fading)
                best = self._nearest_hidden(det, tracks, keep, means, models, moved,
                                            stamp_ns, radius=cfg.reuse_radius,
                                            like=(model, likeness),
                                            below_existence=cfg.reuse_doubtful)
                hidden = far = best is not None
                if far:
                    tid = tracks[best[0]].track_id
                    doubtful = self.reported(tid)
                    # (id, metres, appearance distance, existence) of the track moved
                    info['far'] = (int(tid), round(best[1], 2), round(likeness[tid], 3),
                                   round(float(self.aux[tid].existence), 3))
            if best is None and reused is None and cfg.young_look_alike:
                young = [(n[1], n[0]) for n in near
                         if cfg.looks_alike(n[3]) and self._placed_recently(n[0], stamp_ns)]
                if young:
                    # a track born or moved moments ago lags its person: the detection
                    # beside it that looks like it is that person, not a newcomer
                    info['action'] = f'drop (young look-alike {min(young)[1]})'
                    self._decide(info)
                    return None
            if best is None:
                info['action'] = 'birth' if reused is None else f'reuse {reused}'
                self._decide(info)
                return Birth(model=model, state=state, detection=det, track_id=reused)
        tid = tracks[best[0]].track_id
        again = False
        if not (hidden or beside) and self._placed_recently(tid, stamp_ns):
            again = gains[tid] > cfg.move_again_gain \
                and self._moved_again.get(tid) != self._placed.get(tid)
            if not again:
                info['action'] = f'drop (track {tid} placed recently)'
                self._decide(info)
                return None
            self._moved_again[tid] = int(stamp_ns)
        info['action'] = f'move {tid}' + (' (doubtful, far)' if doubtful
                                          else ' (hidden, far)' if far
                                          else ' (hidden)' if hidden
                                          else ' (beside)' if beside
                                          else ' (again)' if again else '')
        self._decide(info)
        self._placed[tid] = int(stamp_ns)
        self._shown_since[tid] = int(stamp_ns)
        moved.add(tid)
        self.releaser.forget(tid)
        self.aux[tid] = TrackAuxiliary(cfg.existence)
        return Birth(model=models[tid], state=state, detection=det, track_id=tid)

    def _decide(self, info: dict) -> None:
        """Record what happened to a confirmed detection (``decisions``) and log it at debug
        level: the detection's place and score, the tracks compared (id, metres, gain in
        nats per side camera, appearance distance), the support and the action taken."""
        self.decisions.append(info)
        if _log.isEnabledFor(logging.DEBUG):
            _log.debug('detection at (%.2f, %.2f) score %.2f: %s; %s', *info['xy'],
                       info['score'], info.get('action', '?'),
                       ', '.join(f'{k}={v}' for k, v in info.items()
                                 if k not in ('xy', 'score', 'action')))

    def _placed_recently(self, track_id: int, stamp_ns: int) -> bool:
        """The track was born or moved less than ``relocate_interval`` before ``stamp_ns``."""
        since = self._placed.get(track_id)
        return since is not None \
            and (int(stamp_ns) - since) / 1e9 < self.config.relocate_interval

    def _nearest_hidden(self, det: Detection, tracks: Sequence[TrackEstimate],
                        keep: Sequence[int], means: np.ndarray,
                        models: Mapping[int, PersonModel], moved: set[int], stamp_ns: int,
                        radius: float | None = None,
                        like: tuple[PersonModel, dict[int, float]] | None = None,
                        below_existence: float = 0.0) -> tuple[int, float] | None:
        """(index, distance) of the nearest unreported track within ``radius`` (default
        ``relocate_radius``) of the detection (a track whose existence fell below the
        report threshold; or, reported, below ``below_existence``), or None; with ``like``
        (the detection's model, and the cache of appearance distances to it by track id,
        filled here) only a track whose model is within ``reuse_distance`` of that model
        (``reuse_hidden``). Not a track born or moved within ``relocate_interval``: hidden
        again so soon, its model does not explain the person there."""
        best = None
        for k in keep:
            tid = tracks[k].track_id
            if tid in moved or tid not in models:
                continue
            aux = self.aux.get(tid)
            if self.reported(tid) \
                    and not (aux is not None and aux.existence < below_existence):
                continue
            if self._placed_recently(tid, stamp_ns):
                continue
            d = float(np.hypot(*(means[k, [X, Y]] - det.xy)))
            if d > (self.config.relocate_radius if radius is None else radius):
                continue
            if like is not None:
                model, likeness = like
                if tid not in likeness:
                    likeness[tid] = model_distance(models[tid], model)
                if likeness[tid] > self.config.reuse_distance:
                    continue
            if best is None or d < best[1]:
                best = (k, d)
        return best

    def _lagging_beside(self, det: Detection, model: PersonModel,
                        tracks: Sequence[TrackEstimate], keep: Sequence[int],
                        means: np.ndarray, models: Mapping[int, PersonModel],
                        evidence: Mapping[str, FrameEvidence], moved: set[int],
                        stamp_ns: int, info: dict,
                        support: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
                        ) -> tuple[int, float] | None:
        """(index, exclusive support with the detection) of the reported track whose
        person the detection is, or None (``AutoDetectionConfig.beside_support``);
        ``support``: :meth:`_exclusive_support` of the same tracks if already computed.

        A track that fell 0.5-1 m behind its person keeps some of their foreground (the
        corner cameras look along the gap), so it stays reported, while the detector finds
        the person outside its 0.5 m exclusion radius. With the detection as one more
        track, such a track's exclusive support falls below ``beside_support`` (the
        release's measure of a spare track) while it was above before: its foreground was
        the detection's person, and it is moved there instead of a birth beside it. Only
        when exactly one track within ``relocate_radius`` would fall below (in a group
        at the door several do, and the nearest is often not the person's), that track
        within ``beside_radius`` of the detection (one farther off was mostly another
        person's), and not a spare track, one not reported, or one moved within
        ``relocate_interval`` (it would hop through a group; a young track never moved may
        be: a birth that lags its person from the start). A track on a person of its own keeps its
        exclusive support next to a newcomer."""
        cfg = self.config
        keep = list(keep)
        gap = np.linalg.norm(means[keep][:, [X, Y]] - det.xy, axis=1)
        near = np.flatnonzero(gap <= cfg.relocate_radius)
        if not len(near):
            return None
        alone, with_det, spare = support if support is not None else \
            self._exclusive_support(det, model, tracks, keep, means, models, evidence)
        info['beside'] = [(int(tracks[keep[j]].track_id), round(float(alone[j]), 3),
                           round(float(with_det[j]), 3)) for j in near]
        # the one near track the detection would leave spare (NaN, seen nowhere: none);
        # two or more (a group at the door): whose person it is is unclear
        losing = near[with_det[near] < cfg.beside_support]
        if len(losing) != 1:
            return None
        i = int(losing[0])
        if gap[i] > cfg.beside_radius:    # farther off, mostly another person's track
            return None
        k = keep[i]
        tid = tracks[k].track_id
        ref = models.get(tid)
        # a track moved within relocate_interval stays (it would hop through a group); a
        # young one never moved may be taken (a birth lagging its person from the start)
        moved_lately = self._placed_recently(tid, stamp_ns) \
            and self._placed.get(tid, 0) > self._first_seen.get(tid, stamp_ns)
        if spare[i] or tid in moved or ref is None or not ref.view_angles.size \
                or not self.reported(tid) or moved_lately:
            return None
        if not alone[i] >= cfg.beside_support:    # not spare now, spare with it
            return None
        return k, float(with_det[i])

    def _exclusive_support(self, det: Detection, model: PersonModel,
                           tracks: Sequence[TrackEstimate], keep: Sequence[int],
                           means: np.ndarray, models: Mapping[int, PersonModel],
                           evidence: Mapping[str, FrameEvidence]
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Exclusive support (:func:`release.spare_tracks`, side cameras) of the tracks
        ``keep`` (the frame's live tracks) as they are and with the detection added as one
        more track, and whether each is spare now (the release's ``spare_support`` and
        ``spare_radius``).

        A track whose foreground is the detection's person loses it when the detection
        becomes a track: its person is the detection's (a track lagging behind them); a
        track on a person of its own keeps it.

        Returns:
            support without the detection (K,), support with it (K,), spare (K,) bool.
        """
        rel = self.config.release
        side = [n for n in self.side if n in evidence]
        k = len(keep)
        if not side or k == 0:
            nan = np.full(k, np.nan)
            return nan, nan.copy(), np.zeros(k, bool)
        states = np.concatenate([means[list(keep)], det.state[None].astype(np.float64)])
        shapes = [self._shape(models.get(tracks[j].track_id), tracks[j]) for j in keep]
        cams = [self.calibration.cameras[n] for n in side]
        sils = [rasterize(c, states, shapes + [model.shape]) for c in cams]
        # a bootstrap ghost is no one's support (the track lagging on its person's old place)
        fgs = [evidence[n].foreground if evidence[n].ghost is None
               else evidence[n].foreground & ~evidence[n].ghost for n in side]
        least = [rel.min_area * c.width * c.height / (320.0 * 240.0) for c in cams]
        xy = states[:, [X, Y]]
        spare, alone = spare_tracks(fgs, [s.select(0, k) for s in sils], rel.spare_support,
                                    least, xy[:k], rel.spare_radius)
        # min_support 0: nobody is spare, every track's exclusive support is returned
        _, beside = spare_tracks(fgs, sils, 0.0, least)
        return alone, beside[:k], spare

    def _note_reporting(self, stamp_ns: int, tracks: Sequence[TrackEstimate],
                        means: np.ndarray, ended: Sequence[int],
                        models: Mapping[int, PersonModel]) -> None:
        """After a frame's release: where the released tracks were (``reuse_time``) and
        the tracks not reported now or inside an exit (reported without a break since,
        for the duplicate rule)."""
        self._remember_released(stamp_ns, tracks, means, ended, models)
        depth = self.calibration.exit_depth(means[:, [X, Y]]) if len(tracks) \
            else np.zeros(0)
        for k, t in enumerate(tracks):
            if t.track_id not in ended and (not self.reported(t.track_id)
                                            or depth[k] > 0.0):
                self._shown_since[t.track_id] = int(stamp_ns)

    def _remember_released(self, stamp_ns: int, tracks: Sequence[TrackEstimate],
                           means: np.ndarray, ended: Sequence[int],
                           models: Mapping[int, PersonModel]) -> None:
        """Keep where and when the tracks released this frame were, for ``reuse_time``
        (not those released in an entry zone unless ``reuse_in_entry_zones``)."""
        horizon = int(self.config.reuse_time * 1e9)
        expired = [t for t, v in self._released.items() if int(stamp_ns) - v[0] >= horizon]
        for t in expired:
            del self._released[t]
        self._lost_ended.extend(expired)
        if horizon <= 0:
            return
        for k, t in enumerate(tracks):
            if t.track_id not in ended:
                continue
            # without reuse_in_entry_zones a track released in front of the door is its
            # person's exit: the id ends at once
            if not self.config.reuse_in_entry_zones \
                    and self.calibration.in_entry_zone(means[k, [X, Y]])[0]:
                continue
            self._released[int(t.track_id)] = (int(stamp_ns), means[k, [X, Y]],
                                               models.get(t.track_id))

    def _reusable(self, det: Detection, model: PersonModel,
                  models: Mapping[int, PersonModel], info: dict,
                  below: float | None = None) -> int | None:
        """The id of the track released nearest the detection, within ``reuse_radius``
        metres and ``reuse_time`` seconds, not live, whose appearance model is within
        ``reuse_distance`` of the detection's - or, when ``below`` is given, nearer than
        ``below`` (``reuse_before_moving``) - (and forgets it), or None; each candidate's
        distance and model distance go to ``info['reuse']``."""
        best = None
        for tid, (_, xy, old) in self._released.items():
            d = float(np.hypot(*(xy - det.xy)))
            if tid in models or d > self.config.reuse_radius:
                continue
            unlike = model_distance(old, model) if old is not None else 1.0
            info.setdefault('reuse', []).append((int(tid), round(d, 2), round(unlike, 3)))
            fits = unlike <= self.config.reuse_distance if below is None else unlike < below
            if fits and (best is None or d < best[1]):
                best = (tid, d)
        if best is None:
            return None
        del self._released[best[0]]
        return best[0]

    def _duplicate_judge(self, tracks: Sequence[TrackEstimate], means: np.ndarray,
                         models: Mapping[int, PersonModel],
                         evidence: Mapping[str, FrameEvidence]
                         ) -> Callable[[int, int], int | None]:
        """The ``prefer`` of :meth:`Releaser.duplicates`: of two tracks on one place, the
        one whose model explains the image there better by ``duplicate_margin`` nats per
        side camera (003 Eq. 3, each model at the pair's midpoint with its own orientation,
        cameras where both silhouettes are at least half inside the image), or None. Each
        call is kept in ``duplicate_checks`` with both tracks' exclusive support."""
        index = {t.track_id: k for k, t in enumerate(tracks)}

        def prefer(a: int, b: int) -> int | None:
            ka, kb = index[a], index[b]
            ma, mb = models.get(a), models.get(b)
            fits = []
            if ma is not None and mb is not None and ma.view_angles.size \
                    and mb.view_angles.size:
                states = np.stack([means[ka], means[kb]]).astype(np.float64)
                states[:, [X, Y]] = 0.5 * (means[ka, [X, Y]] + means[kb, [X, Y]])
                fits = self._pair_logliks(states, (ma, mb), evidence)
            gain = float(np.mean([f[0] - f[1] for f in fits])) if fits else 0.0
            keep = (a if gain > 0 else b) if abs(gain) > self.config.duplicate_margin \
                else None
            own = self.releaser.exclusive_support()     # this frame's, all tracks present
            support = [round(float(own[k]), 3) if k < len(own) and np.isfinite(own[k])
                       else None for k in (ka, kb)]
            self.duplicate_checks.append({'ids': (int(a), int(b)), 'gain': round(gain, 3),
                                          'cameras': len(fits), 'keep': keep,
                                          'support': support})
            return keep
        return prefer

    def _explains(self, model: PersonModel, track: np.ndarray, candidate: np.ndarray,
                  evidence: Mapping[str, FrameEvidence]) -> float:
        """Mean over side cameras of ``log p(y_c | candidate) - log p(y_c | track)`` under
        the track's appearance model (003 Eq. 3), cameras seeing both silhouettes only."""
        states = np.stack([track, candidate]).astype(np.float64)
        states[1, THETA] = track[THETA]
        gains = [float(ll[1] - ll[0])
                 for ll in self._pair_logliks(states, (model, model), evidence)]
        return float(np.mean(gains)) if gains else float('-inf')

    def _pair_logliks(self, states: np.ndarray, models: tuple[PersonModel, PersonModel],
                      evidence: Mapping[str, FrameEvidence]) -> list[np.ndarray]:
        """(2,) log-likelihoods (003 Eq. 3) of ``models[i]`` at ``states[i]`` (2, 6), one
        per side camera whose image holds at least half of both silhouettes."""
        out = []
        for n in self.side:
            if n not in evidence:
                continue
            cam = self.calibration.cameras[n]
            sil = rasterize(cam, states, [m.shape for m in models])
            if np.any(sil.area < 0.5 * np.maximum(sil.full_area, 1)) or np.any(sil.area <= 0):
                continue
            rel = relative_angle(states[:, THETA], cam.viewing_angle(states[:, [X, Y]]))
            hists = np.stack([m.interpolate(rel[i:i + 1])[0] for i, m in enumerate(models)])
            out.append(single_target_loglik(evidence[n].bins, sil, hists,
                                            sigma=self.config.sigma))
        return out

    @staticmethod
    def _shape(model: PersonModel | None, track: TrackEstimate) -> BodyShape:
        if model is not None:
            return model.shape
        h = track.height if np.isfinite(track.height) and track.height > 0 else 1.75
        return BodyShape(height=float(h))

    def _rescue_exits(self, stamp_ns: int, tracks: Sequence[TrackEstimate],
                      exited: list[int], evidence: Mapping[str, FrameEvidence],
                      sils: Mapping[str, object], means: np.ndarray,
                      shapes: Sequence[BodyShape], tops: np.ndarray) -> list[int]:
        """Of the tracks the exit rule would release, those to release (returned); the
        others are moved back onto a free person on the floor (``exit_rescue``).

        An estimate pushed into the exit while its person stands at the door leaves the
        person untracked on the floor right beside it: the track's reach
        (:meth:`_reach_coverage`, centred on the estimate brought onto the floor) looks for
        them there. A place counts when the cameras on
        the door's wall, which see the doorway but not the corridor, find it covered by
        foreground that no other track explains (mean coverage at least ``exit_rescue``);
        of such places the one best covered in all cameras is taken (the door-wall cameras
        look along the wall and place a person poorly along it). The track restarts there
        with zero velocity (``reach_moves``, same id) and its estimate of this frame is
        moved there too; ``exit_checks`` keeps each decision."""
        cfg = self.config
        x0, y0, x1, y1 = self.calibration.floor
        index = {t.track_id: k for k, t in enumerate(tracks)}
        out = []
        for tid in exited:
            k = index[tid]
            last = self._rescued.get(tid)
            centre = means.copy()
            centre[k, X] = np.clip(means[k, X], x0, x1)
            centre[k, Y] = np.clip(means[k, Y], y0, y1)
            places, rings = self._reach_coverage(k, evidence, sils, centre, shapes, tops)
            on_floor = (places[:, 0] >= x0) & (places[:, 0] <= x1) \
                & (places[:, 1] >= y0) & (places[:, 1] <= y1)
            places, rings = places[on_floor], [r for r, f in zip(rings, on_floor) if f]
            witnesses = self.calibration.doorway_witnesses(places, cfg.release.doorway_band)
            # the door-wall cameras decide whether someone is there (they cannot see the
            # corridor) but look along the wall; where, all cameras together tell
            best, where, fit = 0.0, None, -1.0
            for i, (place, ring) in enumerate(zip(places, rings)):
                cams = [n for n, w in witnesses.items() if w[i] and n in ring] \
                    or [n for n in self.side if n in ring]
                score = float(np.mean([ring[n] for n in cams])) if cams else 0.0
                best = max(best, score)
                overall = float(np.mean(list(ring.values())))
                if score >= cfg.exit_rescue and overall > fit:
                    where, fit = place, overall
            rescue = where is not None and (
                last is None or (int(stamp_ns) - last) / 1e9 >= cfg.relocate_interval)
            self.exit_checks.append({'id': int(tid), 'coverage': round(best, 3),
                                     'overall': round(fit, 3),
                                     'place': None if where is None else
                                     (float(where[0]), float(where[1])),
                                     'rescued': bool(rescue)})
            if not rescue:
                out.append(tid)
                continue
            self._rescued[tid] = int(stamp_ns)
            self.reach_moves[tid] = where
            mean = tracks[k].mean.copy()
            mean[[X, Y]] = where
            mean[[VX, VY]] = 0.0
            tracks[k].mean = mean
        return out

    def _reach_coverage(self, k: int, evidence: Mapping[str, FrameEvidence],
                        sils: Mapping[str, object], means: np.ndarray,
                        shapes: Sequence[BodyShape], tops: np.ndarray, *,
                        centre: bool = False
                        ) -> tuple[np.ndarray, list[dict[str, float]]]:
        """The places (M, 2) of track k's reach (``reach_directions`` places on each of
        the rings of radius ``reach_radius`` / 2 and ``reach_radius`` around its mean, but
        none within the detector's ``exclusion_radius`` of another track) and per place:
        camera -> coverage of its silhouette there (top-down cameras: the
        release's blob, doubled as in :meth:`Releaser.support`), counting only foreground
        that no other track's silhouette (blob) at its mean covers and that is not a
        possible person of the bootstrap (the background's not-yet-known foreground), over
        the whole area: a track beside a tracked person finds no support in that person,
        a track that lost its person at the start no support in their old place. With
        ``centre`` the track's mean itself comes first (whoever is near it), then those
        places (``catch_up`` compares them with it)."""
        cfg = self.config
        if cfg.reach_radius <= 0:
            return np.zeros((0, 2)), []
        angle = np.tile(2.0 * np.pi * np.arange(cfg.reach_directions) / cfg.reach_directions,
                        2)
        radius = np.repeat([0.5 * cfg.reach_radius, cfg.reach_radius], cfg.reach_directions)
        ring = np.repeat(means[k][None], len(angle), axis=0)
        ring[:, X] += radius * np.cos(angle)
        ring[:, Y] += radius * np.sin(angle)
        others = np.delete(np.arange(len(means)), k)
        if len(others) and cfg.detector.exclusion_radius > 0:
            # another track's neighbourhood is its own (as for the detector)
            gap = np.linalg.norm(ring[:, None, :2] - means[None, others, :2], axis=2)
            ring = ring[gap.min(axis=1) > cfg.detector.exclusion_radius]
        if centre:      # the mean itself first, whoever is near
            ring = np.concatenate([means[k][None], ring])
        m = len(ring)
        if m == 0:
            return np.zeros((0, 2)), []
        out: list[dict[str, float]] = [{} for _ in range(m)]
        for n, sil in sils.items():
            if n not in evidence:
                continue
            cam = self.calibration.cameras[n]
            # pixels that are not the track's support: other tracks', bootstrap ghosts
            taken = self.background.model(n).possible_foreground_as_tested.copy()
            if taken.shape != evidence[n].foreground.shape:
                taken = np.zeros(evidence[n].foreground.shape, bool)
            if is_ceiling(cam):
                paint_blobs(taken, cam, means[others, :2], tops[others])
                cov, _ = blob_coverage(cam, evidence[n].foreground & ~taken, ring[:, :2],
                                       np.full(m, tops[k]))
                cov = np.minimum(2.0 * cov, 1.0)
            else:
                paint = taken.view(np.uint8)
                for j in others:
                    _kernels.paint_spans(paint, sil.row, sil.x0, sil.x1, sil.part,
                                         int(sil.offsets[j]), int(sil.offsets[j + 1]), 1,
                                         False)
                fg_free, _, area = span_counts(evidence[n].foreground,
                                               rasterize(cam, ring, shapes[k]), unknown=taken)
                cov = np.where(area > 0, fg_free / np.maximum(area, 1.0), 0.0)
            for i in range(m):
                out[i][n] = float(cov[i])
        return ring[:, [X, Y]], out

    def _ring_evidence(self, ring: Mapping[str, float], cov: Mapping[str, float],
                       weights: Mapping[str, float]) -> tuple[dict[str, float], float]:
        """A reach place's coverages on the track's cameras (those of ``cov``; 0 where the
        place is not seen) and their existence evidence (:func:`coverage_log_ratio`)."""
        on = {n: ring.get(n, 0.0) for n in cov}
        return on, coverage_log_ratio(on, weights, self.config.existence.support_gain)

    def _catch_up(self, t: TrackEstimate, k: int, cov: Mapping[str, float],
                  weights: Mapping[str, float],
                  reach: Callable[..., tuple[np.ndarray, list[dict[str, float]]]]) -> None:
        """``AutoDetectionConfig.catch_up`` for supported track ``t`` (index ``k``;
        ``cov``, ``weights``: its cameras' coverage and evidence weights): restart it at the
        best place of its reach (``reach_moves``, logged in ``catch_ups``) when the free
        foreground there gives positive coverage evidence, better by more than
        ``catch_up`` than the free foreground at its mean. Not when the track or a place
        of its reach lies in an entry zone (a door crowd)."""
        if self.calibration.in_entry_zone(t.mean[[X, Y]])[0]:
            return              # before the reach is computed: most door tracks stop here
        places, rings = reach(k, centre=True)   # the mean first, then its reach
        if len(places) < 2 or self.calibration.in_entry_zone(places[1:]).any():
            return
        free = [self._ring_evidence(r, cov, weights)[1] for r in rings]
        j = 1 + int(np.argmax(free[1:]))
        if free[j] > 0.0 and free[j] - free[0] > self.config.catch_up:
            self.reach_moves[t.track_id] = places[j]
            self.catch_ups.append({'id': int(t.track_id), 'xy': [float(v) for v in places[j]],
                                   'gain': round(free[j] - free[0], 3)})

    def _visibility_particles(self, tracks: Sequence[TrackEstimate],
                              models: Mapping[int, PersonModel], shapes: Sequence[BodyShape]
                              ) -> tuple[np.ndarray, np.ndarray, list[BodyShape]]:
        """A few posterior particles (P, 6) of every track with a model (001 Eq. 18: particle
        average), the index (P,) of their track and their shapes."""
        cfg = self.config
        rows, owner, part_shapes = [], [], []
        for k, t in enumerate(tracks):
            model = models.get(t.track_id)
            if model is None or not getattr(model, 'view_angles', np.zeros(0)).size:
                continue
            if t.particles is not None and len(t.particles):
                p = t.particles
                w = t.weights if t.weights is not None else np.full(len(p), 1.0 / len(p))
                # systematic selection at the weights' quantiles (no draw: a shared
                # generator would tie every track's sample to the number of tracks)
                idx = systematic_indices(w[None], np.array([w.sum()]), _MID,
                                         min(cfg.visibility_particles, len(p)))[0]
                rows.append(p[idx])
            else:
                rows.append(t.mean[None])
            owner.extend([k] * len(rows[-1]))
            part_shapes.extend([shapes[k]] * len(rows[-1]))
        parts = np.concatenate(rows) if rows else np.zeros((0, 6))
        return parts, np.asarray(owner, dtype=np.int64), part_shapes

    def _auxiliary(self, dt: float, colour: Callable[[str], np.ndarray | None],
                   tracks: Sequence[TrackEstimate],
                   models: Mapping[int, PersonModel], parts: np.ndarray, owner_arr: np.ndarray,
                   part_sils: Mapping[str, object], coverage: Mapping[str, np.ndarray],
                   reach: Callable[[int], tuple[np.ndarray, list[dict[str, float]]]] | None
                   = None) -> None:
        """Visibility and existence of every track (001) from the appearance likelihood of
        its particles ``parts`` (``owner_arr``: their track) rasterised in ``part_sils``;
        ``colour(camera)`` gives the frame's colour bins of a side camera; ``reach(k)`` the
        coverages of track k's reach ring (:meth:`_reach_coverage`)."""
        cfg = self.config
        hidden = -cfg.clutter_distance ** 2 / (2.0 * cfg.sigma ** 2)    # 001 Eq. 23
        has_particles = len(parts) > 0
        loglik: dict[str, np.ndarray] = {}
        if has_particles:
            cams = [n for n in self.side if n in part_sils and colour(n) is not None]
            # the tracks' key views, interpolated lazily per particle and camera at the
            # relative viewing angles (003 Eq. 1-2), as in the filter's likelihood
            with_model, target = np.unique(owner_arr, return_inverse=True)
            refs = [models[tracks[k].track_id] for k in with_model]
            key = key_view_stack(refs)
            va, vb, wa = view_weights([self.calibration.cameras[n] for n in cams], parts,
                                      target.ravel(), refs)
            for c, n in enumerate(cams):
                sil = part_sils[n]
                ll = key_view_loglik(colour(n), sil, key, target.ravel(), va[c], vb[c], wa[c],
                                     sigma=cfg.sigma)
                loglik[n] = np.where(sil.area > 0, ll, -np.inf)
        for k, t in enumerate(tracks):
            aux = self.aux.setdefault(t.track_id, TrackAuxiliary(cfg.existence))
            vis: dict[str, float] = {}
            hid: dict[str, float] = {}
            if has_particles:
                sel = owner_arr == k
                if sel.any():
                    for n, ll in loglik.items():
                        if np.isfinite(ll[sel]).any():
                            vis[n] = predictive_loglik(ll[sel])              # 001 Eq. 18
                            hid[n] = hidden
            cov = {n: float(c[k]) for n, c in coverage.items() if np.isfinite(c[k])}
            # evidence weights: w* of the tracking cameras (top-down cameras are not used by
            # the filter and weigh 1); with a top-down camera, which decides the release,
            # the side cameras' support counts less (their silhouettes are more sensitive
            # to position errors and occlusion)
            side_w = cfg.side_weight if self.ceiling else 1.0
            weights = {n: (float(t.visible_fraction.get(n, 1.0)) * side_w
                           if n in self.side else 1.0) for n in set(cov) | set(vis)}
            best = (coverage_log_ratio(cov, weights, cfg.existence.support_gain)
                    if reach is not None and cov else 0.0)
            if best < 0.0:
                # the track's reach: its best place counts (AutoDetectionConfig.reach_radius)
                places, rings = reach(k)
                for place, ring in zip(places, rings):
                    ring, evidence = self._ring_evidence(ring, cov, weights)
                    if evidence > best:
                        cov, best = ring, evidence
                        if cfg.reach_move and evidence > 0.0:
                            self.reach_moves[t.track_id] = place
            elif cfg.reach_move and np.isfinite(cfg.catch_up) and cov and reach is not None:
                self._catch_up(t, k, cov, weights, reach)
            aux.update(dt, loglik_visible=vis, loglik_hidden=hid, coverage=cov,
                       visible_fraction=weights)
            t.visibility = dict(aux.visibility)
            t.existence = float(aux.existence)
