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
            is not its person. Also :attr:`alike_distance`.
        look_alike_margin: nats per side camera >= 0; how much worse than its own place
            a track's model may explain a strong detection (``beside_threshold``) that
            looks like it (``alike_distance``) for the detection to move the track, when
            the detection would leave the track less than :attr:`move_support`; 0: a
            look-alike needs a positive gain like any other. Catches tracks left behind
            where their person turned.
        relocate_interval: seconds after a track was born or moved during which a detection
            does not move it again but is dropped (a young model explains several people
            in a group about equally well: the track would hop between them), unless its
            appearance gain is positive (the track's model explains the detection better
            than the track's own place): then it is moved again, once. A confirmed
            detection that would start a new track within ``relocate_radius`` of a track
            that is not reported (existence below the report threshold: it lost its
            person) moves that track instead, whatever the gain (the nearest such track
            not placed within ``relocate_interval``).
        reuse_time: seconds; a released track is *lost* for ``reuse_time``: a new track
            born within :attr:`reuse_radius` of where it was released takes its id (its
            person re-found) when the two look alike (``alike_distance``). The id ends
            (:meth:`finished`) only when that time has passed unused, so an id never comes
            back after it ended. 0 ends released tracks at once. The time should cover a
            person standing still after being lost (a few seconds). A detection that would
            start a new track moves instead the nearest hidden track (not reported, or
            reported with an existence below :attr:`reuse_doubtful`; not placed within
            ``relocate_interval``) within :attr:`reuse_radius` whose model is within
            ``alike_distance`` of the detection's: a hidden track is given back its person
            like a lost one.
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
        beside_threshold: smallest detection score (the detector's combined log response)
            for a birth within ``relocate_radius`` of a track that the detection did not
            move: weak detections beside a track are mostly the fringe of that track's
            person or a gap between people; 0 keeps the detector's threshold alone.
    """

    background: BackgroundConfig = field(default_factory=BackgroundConfig)
    detector: DetectorConfig = field(default_factory=DetectorConfig)
    release: ReleaseConfig = field(default_factory=ReleaseConfig)
    acquisition: AcquisitionConfig = field(default_factory=AcquisitionConfig)
    existence: AuxiliaryConfig = field(default_factory=AuxiliaryConfig)
    adaptation: AdaptationConfig = field(default_factory=AdaptationConfig)
    clutter_distance: float = 0.5
    look_alike_margin: float = 6.0
    relocate_interval: float = 2.0
    reuse_time: float = 3.0
    duplicate_margin: float = 8.0
    reach_radius: float = 0.5
    reach_age: float = 4.0
    beside_threshold: float = 3.0

    @property
    def alike_distance(self) -> float:
        """Appearance distance (003 Eq. 4, between two appearance models) at most which a
        track's model and a detection's show the same person: ``clutter_distance``, the
        distance at which a model's likelihood is the clutter likelihood ``p_0`` (001
        Eq. 23), so that a model nearer than it is likelier the person than clutter (a
        log-likelihood ratio above 0). A strong detection that the track's model explains
        worse than the track's own estimate (gain at most 0) moves only such a track, and
        only such a lost or hidden track takes a detection's person back."""
        return self.clutter_distance

    @property
    def relocate_radius(self) -> float:
        """Metres; a confirmed detection this close to a current track is compared with the
        track's appearance model before it may start a new track: the appearance gain
        (:meth:`AutoDetection._explains`: mean log-likelihood ratio per side camera, 003
        Eq. 3 under the track's model, of the detection's place over the track's
        estimate) decides whether it is the track's person (:meth:`gain_gate`). It is the
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
        """Metres from a lost or hidden track within which a detection may be its person:
        ``relocate_radius`` (how far a supported track may lag its person) widened by
        :data:`WALK_SPEED` over the release's ``timeout`` (how long the person may have
        walked on while the track was unsupported before it was released)."""
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

    def looks_alike(self, unlike: float) -> bool:
        """Whether a track whose model is ``unlike`` (appearance distance) from a
        detection's looks like it (``alike_distance``)."""
        return unlike <= self.alike_distance

    def gain_gate(self, score: float, gain: float, unlike: float) -> str | None:
        """Whether the appearance gain (003 Eq. 3, nats per side camera) lets a detection
        of ``score`` move a track whose model is ``unlike`` (appearance distance) from the
        detection's: 'move'; 'unlike' when the gain is in ``(-look_alike_margin, 0]`` of
        a strong detection and the track does not look like the detection
        (``alike_distance`` keeps it back); None when the gain is too low. A strong
        detection (``beside_threshold``) needs a positive gain, or a look-alike track
        one above ``-look_alike_margin``. A weak detection's own evidence (its score, a
        log response) falls short of ``beside_threshold``: the gain must make up the
        shortfall, ``gain > beside_threshold - score``, with no look-alike allowance
        (weak detections beside a track are often a neighbour's fringe)
        (:meth:`AutoDetection._identify`)."""
        if score < self.beside_threshold:
            return 'move' if gain > self.beside_threshold - score else None
        if gain > 0.0:
            return 'move'
        if self.looks_alike(unlike):
            return 'move' if gain > -self.look_alike_margin else None
        return 'unlike' if gain > -self.look_alike_margin else None

    def __post_init__(self) -> None:
        if not (np.isfinite(self.look_alike_margin) and self.look_alike_margin >= 0):
            raise DetectionError(f'look_alike_margin must be a finite number >= 0, got '
                                 f'{self.look_alike_margin}')
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
