"""Parameters of the automatic detection pipeline (:class:`AutoDetectionConfig`) and what it
hands the tracker (:class:`Birth`)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mbtrack_ros.core.appearance import PersonModel
from mbtrack_ros.core.detection import DetectionError
from mbtrack_ros.core.detection.acquisition import AcquisitionConfig
from mbtrack_ros.core.detection.adaptation import AdaptationConfig
from mbtrack_ros.core.detection.background import BackgroundConfig
from mbtrack_ros.core.detection.detector import Detection, DetectorConfig
from mbtrack_ros.core.detection.release import ReleaseConfig
from mbtrack_ros.core.existence import AuxiliaryConfig

__all__ = ['AutoDetectionConfig', 'Birth', 'WALK_SPEED']

WALK_SPEED = 0.5    # m/s, a slow walk: how far a person gets from an unsupported track


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
        clutter_distance: Bhattacharyya distance whose likelihood is the "not visible"
            clutter likelihood ``p_0`` (001 Eq. 23): what a model scores on something that
            is not its person. Also the zero of the prior appearance ratio of two models
            (:class:`.likeness.AppearanceRatio`, which the tracks' own samples then
            calibrate).
        relocate_interval: seconds after a track was born or moved during which it lags
            its person and its young model explains several people in a group about
            equally well: a detection assigned to it (:mod:`.association`) is dropped, not
            moved onto (the track would hop between people), unless its appearance gain is
            positive (the track's model explains the detection better than the track's own
            place): then it is moved again, once; a detection beside it that looks like it
            (:meth:`.likeness.AppearanceRatio.looks_alike`) is that person, not a newcomer
            (assigned to it, dropped).
        reuse_time: seconds; a released track is *lost* for ``reuse_time``: a detection
            near where it was released (within :attr:`reuse_radius`, widened by
            :data:`WALK_SPEED` over the time since) that does not look unlike it may be
            assigned to it and take its id (its person re-found; the place and
            appearance ratios of :mod:`.association`). The id ends
            (:meth:`finished`) only when that time has passed unused, so an id never comes
            back after it ended. 0 ends released tracks at once. The time should cover a
            person standing still after being lost (a few seconds).
        duplicate_margin: nats per side camera; of two tracks on one person (closer than
            the release's ``merge_radius`` for its ``merge_time``) keep the one whose
            appearance model explains the image where they are better (003 Eq. 3, both
            models at the pair's midpoint) by more than this
            (:meth:`AutoDetection._duplicate_judge`); ``inf`` disables. Large enough that
            a model acquired moments ago (which fits its own view best) does not win alone.
        reach_radius: metres; a track whose coverage evidence for existence is negative
            at its mean is also judged at eight places on each of two rings around it
            (radius half and all of ``reach_radius``), on the foreground no other track's
            silhouette covers, and the best place counts: a track that fell behind a person
            who started walking stays reported while the person is within the detector's
            ``exclusion_radius`` (where the detector does not look for them), and when
            that place has positive coverage evidence the track is restarted there (same
            id and velocity, :attr:`AutoDetection.reach_moves`; the tracker moves it after
            the frame's output) so that it catches up with its person; 0 disables.
        reach_age: seconds a track must have existed before it has a reach: a false birth
            (a shadow, a ghost, the fringe of a person) would keep itself alive on the
            foreground near it, and false births are mostly released within a few seconds
            (the release's ``timeout`` after they lose support, or the existence process's
            fall); longer keeps a young track of a real person who walks off from it less
            well.
        beside_threshold: nats; the prior log-odds against a birth within
            ``relocate_radius`` of a track, subtracted from the detection's score (the
            detector's combined log response) in the birth's ratio of the association:
            weak detections beside a track are mostly the fringe of that track's person or
            a gap between people; 0 keeps the detector's threshold alone.
    """

    background: BackgroundConfig = field(default_factory=BackgroundConfig)
    detector: DetectorConfig = field(default_factory=DetectorConfig)
    release: ReleaseConfig = field(default_factory=ReleaseConfig)
    acquisition: AcquisitionConfig = field(default_factory=AcquisitionConfig)
    existence: AuxiliaryConfig = field(default_factory=AuxiliaryConfig)
    adaptation: AdaptationConfig = field(default_factory=AdaptationConfig)
    clutter_distance: float = 0.5
    relocate_interval: float = 2.0
    reuse_time: float = 3.0
    duplicate_margin: float = 8.0
    reach_radius: float = 0.5
    reach_age: float = 4.0
    beside_threshold: float = 3.0

    @property
    def relocate_radius(self) -> float:
        """Metres; a confirmed detection this close to a current track is compared with the
        track's appearance model before it may start a new track: the appearance gain
        (:meth:`AutoDetection._explains`: mean log-likelihood ratio per side camera, 003
        Eq. 3 under the track's model, of the detection's place over the track's
        estimate) weighs whether it is the track's person (:meth:`move_llr`). It is the
        release's ``spare_radius``: the largest distance at which two hypotheses (two
        tracks, or a track and a detection) are taken to be possibly of one person."""
        return self.release.spare_radius

    @property
    def move_support(self) -> float:
        """Exclusive support (:func:`~.release.spare_tracks`: foreground no other track
        covers, per silhouette pixel) at which a track stands on a person of its own: the
        release's ``spare_support``, below which a track is spare. A detection does not
        move a track that keeps this much with the detection as one more track (it is
        somebody else); ``inf`` (no track is kept from a move) when ``spare_support`` is 0
        (no track is ever spare)."""
        return self.release.spare_support if self.release.spare_support > 0 else np.inf

    @property
    def reuse_radius(self) -> float:
        """Metres from a hidden track, or from a lost one when it is released, within
        which a detection may be its person: ``relocate_radius`` (how far a supported
        track may lag its person) widened by :data:`WALK_SPEED` over the release's
        ``timeout`` (how long the person may have walked on while the track was
        unsupported before it was released); a lost track's gate widens on at that speed
        while it is lost (:mod:`.association`)."""
        return self.relocate_radius + WALK_SPEED * self.release.timeout

    @property
    def reuse_doubtful(self) -> float:
        """Existence probability below which a reported track counts as hidden for the
        reuse (logged "move N (doubtful, far)"): the existence a track is born with
        (``existence.initial_existence``, 001 §3.2); the track a detection moves there is a
        hypothesis no better supported than the birth it replaces. With
        ``existence.report_threshold`` 0 every track is reported, so this level is what
        lets the reuse take hidden ones."""
        return self.existence.initial_existence

    def move_llr(self, score: float, gain: float, appearance: float) -> float:
        """Log-likelihood ratio (nats) of "the detection (of ``score``) is the person of a
        track" over "it is a new person": the appearance gain (003 Eq. 3, nats per side
        camera: the track's model at the detection over at the track's own estimate),
        plus, for a strong detection (``beside_threshold``), the appearance ratio of the
        two models ``appearance`` (nats, :meth:`.likeness.AppearanceRatio.llr`) floored at
        0 (a track left behind where its person turned explains them worse than its own
        place, but still looks like them; a model unlike the detection says it is not
        visible there, not that it is elsewhere). The association adds the detection's
        own ratio (its score less ``beside_threshold``), so that a weak detection moves a
        track only when the gain makes up its shortfall (weak detections beside a track
        are often a neighbour's fringe, which looks like the neighbour)."""
        strong = score >= self.beside_threshold
        return float(gain) + (max(0.0, float(appearance)) if strong else 0.0)

    def __post_init__(self) -> None:
        if not self.duplicate_margin >= 0:
            raise DetectionError(f'duplicate_margin must be >= 0, got {self.duplicate_margin}')
        if not self.reuse_time >= 0:
            raise DetectionError(f'reuse_time must be >= 0, got {self.reuse_time}')
        if not self.clutter_distance > 0:
            raise DetectionError(f'clutter_distance must be > 0, got {self.clutter_distance}')
        if not (np.isfinite(self.beside_threshold) and self.beside_threshold >= 0):
            raise DetectionError(f'beside_threshold must be a finite number >= 0, got '
                                 f'{self.beside_threshold}')
        if not (self.reach_radius >= 0 and self.reach_age >= 0):
            raise DetectionError('reach_radius and reach_age must be >= 0')


@dataclass
class Birth:
    """A new person to add to the tracker, or (``track_id`` set) a current track that
    drifted off its person and must be restarted at the detection, keeping its id."""

    model: PersonModel
    state: np.ndarray
    detection: Detection
    track_id: int | None = None
