"""The multi-person tracker: owns the tracks, runs one filter per frame, reports results.

::

    tracker = Tracker(calibration, TrackerConfig(algorithm='hjs'), rng=np.random.default_rng(0))
    tid = tracker.add_track(model, state, stamp_ns)    # ids 1, 2, ... never reused (unless
                                                       # the opt-in detection reuse_time > 0)
    result = tracker.step(stamp_ns, images)            # FrameResult (core/state.py)

Time comes only from the integer nanosecond stamps: each step predicts over
``(stamp_ns - previous stamp) / 1e9`` seconds. A stamp earlier than the previous one raises
:class:`TrackerError` (the caller resets the tracker, e.g. when a bag loops). The algorithm
is picked by name from the filter registry (:mod:`mbtrack_ros.core.filters`): ``hjs``,
``separable``, ``joint`` and the association baselines once registered.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace, fields

import numpy as np

from mbtrack_ros.core.camera import Camera, RoomCalibration
from mbtrack_ros.core.dynamics import DynamicsError, MotionConfig
from mbtrack_ros.core.filters import FilterConfig, FilterError, TrackingFilter, make_filter
from mbtrack_ros.core.state import SIT, STATE_DIM, FrameResult, TrackEstimate, VX, VY, X, Y

__all__ = ['MAX_JOINT_PARTICLES', 'MAX_PARTICLES', 'REFERENCE_PIXELS', 'Tracker', 'TrackerConfig',
           'TrackerError', 'length_scale']


#: most particles per target (``TrackerConfig.particles``, node ``tracker.particles``)
MAX_PARTICLES = 100_000
#: most joint particles (``TrackerConfig.joint_particles``, node ``tracker.joint_particles``)
MAX_JOINT_PARTICLES = 1_000_000


class TrackerError(ValueError):
    """Invalid configuration, unknown track, or stamps going backwards."""


@dataclass(frozen=True)
class TrackerConfig:
    """Everything that parameterises a tracking run (validated on construction).

    Attributes:
        algorithm: 'hjs', 'hjs-groups', 'separable', 'joint' (or a registered baseline:
            'pdaf', ...).
        particles: particles per target (HJS, separable; 000 §VI: 100).
        joint_particles: joint particles of the joint filter (000 §VI-B: 10^4).
        sigma: likelihood width sigma (000 Eq. 19).
        d_occ: occlusion penalty d_occ (000 Eq. 26).
        coverage_gain: ``k`` of the foreground-coverage term ``k f_c`` per camera in the
            particle log-likelihood with detection on (``LikelihoodConfig.coverage_gain``),
            nats per camera at full coverage; 0: colour alone.
        min_inside_share: a camera that sees less of a target's silhouettes inside its
            image (on average over its particles) says nothing about the target
            (``LikelihoodConfig.min_inside_share``), share in [0, 1]; 0: only the particles
            it does not see at all get their target's mean there.
        min_visible_share: a camera in which a target is hidden (its prior-expected
            visible fraction sum(w*) / area below this) says nothing about the target
            (``LikelihoodConfig.min_visible_share``), share in [0, 1]; 0: never.
        mrf_radius: spatial-exclusion radius r of the MRF prior (000 Eq. 16), metres, > 0.
            000 §VI-A uses 0.4; people who stand or walk side by side are 0.42-0.5 m apart
            centre to centre, and a radius near that pushes their tracks apart. 0.3 lies
            below the shape model's thinnest extent (the width seen from the side, 0.7 x
            0.5 m = 0.35 m, 003 §2.1): it forbids only overlapping bodies.
            ``mbtrack experiments`` keeps 0.4 for 000 §VI.
        mrf_epsilon: floor of the exclusion potential.
        use_mrf: apply the MRF prior (False = ablation of 000 §VI-C).
        theta_bp: BP stopping threshold (000 Eq. 43: 0.01).
        max_bp_iterations: BP iteration limit.
        motion: motion-model noise (:class:`~mbtrack_ros.core.dynamics.MotionConfig`).
        init_position_spread: m, spread of a new track's particles.
        init_velocity_spread: m/s, spread of a new track's velocities.
        seed: seed of the default random generator (None = fresh entropy).
        release_time: s without foreground support before a track is released (003 §4.3).
        release_recover_time: s of support in a row after which the unsupported time of a
            track that was spare in it starts again (``ReleaseConfig.recover_time``; None:
            its default, 0: one supported frame).
        spare_support: exclusive support below which a track overlapping another one is
            spare and released like an unsupported one (``ReleaseConfig.spare_support``;
            None: its default, 0: off).
        reuse_time: s during which a released track is only lost and a person re-found
            nearby who looks like it takes its id back (``AutoDetectionConfig.reuse_time``;
            None: its default, 0: released tracks end at once).
        detection_threshold: smallest combined log response of a detection (None: the
            detector's default).
        beside_threshold: smallest score of a detection that starts a track within 1 m of
            another track (``AutoDetectionConfig.beside_threshold``; None: its default,
            0: the detector's threshold alone).
        detection: automatic detection, model acquisition and release of people (003 §4)
            with visibility/existence probabilities (001), see
            :mod:`mbtrack_ros.core.detection.manager`.
        subsample: the likelihood reads every k-th image row of the silhouettes (1: all
            rows; 2-8: less CPU, less accuracy).
        pipeline_search: with detection, run the search for new people of frame t on the
            detection's worker thread while frame t+1 is filtered, and add its people after
            frame t+1's result (one frame later than without; deterministic, the same live
            and offline). See :meth:`Tracker.step`.
        detection_every: with detection, run the whole detection pipeline (foreground,
            release, visibility and existence, background update, search) on every k-th
            frame set only (the 1st, (k+1)-th, ... since the start or a reset); the frame
            sets between are only filtered and report the tracks with the visibility and
            existence of the last detection frame set (1: every frame set; larger: less
            CPU, people found later and kept less well).
        working_pixels: pixels per camera image the tracker works on (default 320 x 240 =
            76800): a camera with more is resized to about that many square pixels
            (``Camera.at_most``: by ``sqrt(working_pixels / (w h))`` when its pixels are
            square, never enlarged; :meth:`Tracker.step` resizes each image
            once, the intrinsics are scaled to match). Every pixel-unit setting (the
            detection's morphology, mask growth and edge validation, the likelihood's
            smallest visible area) is given at 320 x 240 and scaled with the working size
            (:data:`REFERENCE_PIXELS`), so the same room gives the same results from a
            640 x 480 or a 1920 x 1080 camera. Fewer pixels (e.g. 19200, 160 x 120): less
            CPU, less accuracy. Tracks are in room coordinates whatever the size.
        adaptation_rate: with detection, blending rate of the slow, occlusion-aware
            appearance-model adaptation of confirmed tracks (``AdaptationConfig.rate``,
            :mod:`mbtrack_ros.core.detection.adaptation`; None: its default, 0.05), per
            adaptation in [0, 1]; 0 = off.
    """

    algorithm: str = 'hjs'
    particles: int = 100
    joint_particles: int = 10_000
    sigma: float = 0.12
    d_occ: float = 0.15
    coverage_gain: float = 2.0
    min_inside_share: float = 0.5
    min_visible_share: float = 0.1
    mrf_radius: float = 0.3
    mrf_epsilon: float = 1e-3
    use_mrf: bool = True
    theta_bp: float = 0.01
    max_bp_iterations: int = 20
    motion: MotionConfig = field(default_factory=MotionConfig)
    init_position_spread: float = 0.05
    init_velocity_spread: float = 0.1
    seed: int | None = None
    detection: bool = False
    release_time: float = 1.0
    release_recover_time: float | None = None
    detection_threshold: float | None = None
    beside_threshold: float | None = None
    spare_support: float | None = None
    reuse_time: float | None = None
    subsample: int = 1
    pipeline_search: bool = False
    detection_every: int = 1
    working_pixels: int = 76_800
    adaptation_rate: float | None = None

    def __post_init__(self) -> None:
        def bad(msg: str) -> None:
            raise TrackerError(f'invalid tracker config: {msg}')

        if not isinstance(self.algorithm, str) or not self.algorithm:
            bad(f'algorithm must be a name, got {self.algorithm!r}')
        for name in ('particles', 'joint_particles', 'max_bp_iterations', 'subsample',
                     'detection_every'):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                bad(f'{name} must be an integer >= 1, got {value!r}')
        for name, cap in (('particles', MAX_PARTICLES), ('joint_particles',
                                                         MAX_JOINT_PARTICLES)):
            if getattr(self, name) > cap:  # memory grows linearly with the particles
                bad(f'{name} must be at most {cap}, got {getattr(self, name)}')
        for name in ('min_inside_share', 'min_visible_share'):
            share = getattr(self, name)
            if isinstance(share, bool) or not (isinstance(share, (int, float))
                                               and 0 <= share <= 1):
                bad(f'{name} must be a number in [0, 1], got {share!r}')
        for name in ('sigma', 'theta_bp'):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and np.isfinite(value) and value > 0):
                bad(f'{name} must be a finite number > 0, got {value!r}')
        for name in ('d_occ', 'coverage_gain', 'mrf_radius', 'init_position_spread',
                     'init_velocity_spread'):
            value = getattr(self, name)
            if isinstance(value, bool) or not (isinstance(value, (int, float))
                                               and np.isfinite(value) and value >= 0):
                bad(f'{name} must be a finite number >= 0, got {value!r}')
        if not (isinstance(self.mrf_epsilon, (int, float)) and 0 < self.mrf_epsilon <= 1):
            bad(f'mrf_epsilon must be in (0, 1], got {self.mrf_epsilon!r}')
        if not isinstance(self.motion, MotionConfig):
            bad('motion must be a MotionConfig')
        for name in ('detection', 'pipeline_search'):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                bad(f'{name} must be true or false, got {getattr(self, name)!r}')
        if not (isinstance(self.release_time, (int, float)) and np.isfinite(self.release_time)
                and self.release_time > 0):
            bad(f'release_time must be a finite number of seconds > 0, '
                f'got {self.release_time!r}')
        if self.release_recover_time is not None and not (
                isinstance(self.release_recover_time, (int, float))
                and not isinstance(self.release_recover_time, bool)
                and 0 <= self.release_recover_time < np.inf):
            bad(f'release_recover_time must be a finite number of seconds >= 0, '
                f'got {self.release_recover_time!r}')
        if self.detection_threshold is not None and not (
                isinstance(self.detection_threshold, (int, float))
                and np.isfinite(self.detection_threshold)):
            bad(f'detection_threshold must be a finite number, got {self.detection_threshold!r}')
        if self.beside_threshold is not None and not (
                isinstance(self.beside_threshold, (int, float))
                and not isinstance(self.beside_threshold, bool)
                and 0 <= self.beside_threshold < float('inf')):
            bad(f'beside_threshold must be a finite number >= 0, got {self.beside_threshold!r}')
        if self.spare_support is not None and not (
                isinstance(self.spare_support, (int, float)) and 0 <= self.spare_support <= 1):
            bad(f'spare_support must be a number in [0, 1], got {self.spare_support!r}')
        if self.reuse_time is not None and (
                isinstance(self.reuse_time, bool) or not isinstance(self.reuse_time, (int, float))
                or not 0 <= self.reuse_time < float('inf')):
            bad(f'reuse_time must be a number >= 0, got {self.reuse_time!r}')
        if self.adaptation_rate is not None and (
                isinstance(self.adaptation_rate, bool) or not (
                    isinstance(self.adaptation_rate, (int, float))
                    and 0 <= self.adaptation_rate <= 1)):
            bad(f'adaptation_rate must be a number in [0, 1], got {self.adaptation_rate!r}')
        if isinstance(self.working_pixels, bool) or not (
                isinstance(self.working_pixels, (int, np.integer))
                and MIN_WORKING_PIXELS <= self.working_pixels):
            bad(f'working_pixels must be an integer >= {MIN_WORKING_PIXELS}, got '
                f'{self.working_pixels!r}')
        if self.seed is not None and (isinstance(self.seed, bool)
                                      or not isinstance(self.seed, (int, np.integer))):
            bad(f'seed must be an integer or None, got {self.seed!r}')

    def likelihood_config(self):
        """The likelihood parameters this configuration sets (000 Eq. 19, 26; the cameras
        that say nothing about a target; the foreground-coverage term), at full image
        size."""
        from mbtrack_ros.core.likelihood import LikelihoodConfig

        return LikelihoodConfig(sigma=float(self.sigma), d_occ=float(self.d_occ),
                                subsample=int(self.subsample),
                                min_inside_share=float(self.min_inside_share),
                                min_visible_share=float(self.min_visible_share),
                                coverage_gain=float(self.coverage_gain))

    def working_calibration(self, calibration: RoomCalibration) -> RoomCalibration:
        """The cameras at the size the tracker works on (``working_pixels``): each camera
        with more pixels resized to about that many square pixels (``Camera.at_most``)."""
        return replace(calibration, cameras={name: cam.at_most(self.working_pixels)
                                             for name, cam in calibration.cameras.items()})

    def detection_config(self, length_scale: float = 1.0):
        """The automatic-detection parameters this configuration sets (003 §4), with its
        pixel lengths (given at 320 x 240) multiplied by ``length_scale`` (the working
        size's, :func:`length_scale`)."""
        from mbtrack_ros.core.detection.detector import DetectorConfig
        from mbtrack_ros.core.detection.manager import AutoDetectionConfig
        from mbtrack_ros.core.detection.release import ReleaseConfig

        detector = DetectorConfig() if self.detection_threshold is None else \
            replace(DetectorConfig(), threshold=float(self.detection_threshold))
        release = replace(ReleaseConfig(), timeout=float(self.release_time))
        if self.spare_support is not None:
            release = replace(release, spare_support=float(self.spare_support))
        if self.release_recover_time is not None:
            release = replace(release, recover_time=float(self.release_recover_time))
        config = AutoDetectionConfig(detector=detector, release=release)
        if self.adaptation_rate is not None:
            config = replace(config, adaptation=replace(config.adaptation,
                                                        rate=float(self.adaptation_rate)))
        if self.reuse_time is not None:
            config = replace(config, reuse_time=float(self.reuse_time))
        if self.beside_threshold is not None:
            config = replace(config, beside_threshold=float(self.beside_threshold))
        return _pixels_scaled(config, float(length_scale))

    def filter_config(self) -> FilterConfig:
        """The particle-filter parameters of this configuration."""
        return FilterConfig(
            particles=int(self.particles), joint_particles=int(self.joint_particles),
            motion=self.motion, use_mrf=bool(self.use_mrf), mrf_radius=float(self.mrf_radius),
            mrf_epsilon=float(self.mrf_epsilon), theta_bp=float(self.theta_bp),
            max_bp_iterations=int(self.max_bp_iterations),
            init_position_spread=float(self.init_position_spread),
            init_velocity_spread=float(self.init_velocity_spread))

    @classmethod
    def from_dict(cls, values: dict) -> TrackerConfig:
        """Build from plain values (YAML/CLI); ``motion`` may be a dict of MotionConfig keys."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise TrackerError(f'invalid tracker config: unknown key(s) {", ".join(unknown)}')
        values = dict(values)
        if isinstance(values.get('motion'), dict):
            try:
                values['motion'] = MotionConfig(**values['motion'])
            except (TypeError, DynamicsError) as err:
                raise TrackerError(f'invalid tracker config: motion: {err}') from err
        return cls(**values)


#: pixels of the image size at which every pixel-unit default is given (320 x 240)
REFERENCE_PIXELS = 320 * 240
#: smallest ``working_pixels`` (80 x 60)
MIN_WORKING_PIXELS = 80 * 60


def length_scale(calibration: RoomCalibration) -> float:
    """Factor of pixel lengths at the cameras' (working) size relative to 320 x 240:
    ``sqrt(pixels / REFERENCE_PIXELS)`` of the median camera (one factor for the room;
    cameras of one rig have similar sizes)."""
    pixels = sorted(c.width * c.height for c in calibration.cameras.values())
    if not pixels:
        return 1.0
    return float(np.sqrt(pixels[len(pixels) // 2] / REFERENCE_PIXELS))


def _length(pixels: int, scale: float) -> int:
    """A length in pixels at 320 x 240, at an image size with length factor ``scale``
    (rounded half up)."""
    return int(np.floor(pixels * scale + 0.5))


def _pixels_scaled(config, scale: float):
    """``AutoDetectionConfig`` with its pixel lengths (given at 320 x 240) scaled by the
    working size's length factor ``scale``: background morphology and mask growth, the
    person cue's dilations, the edge validation. Its areas (``min_area``,
    ``min_blob_area``) are given at 320x240 and scaled with the image area where they are
    used, and metres need nothing."""
    if scale == 1.0:
        return config
    bg = config.background
    # kernel diameters 2r + 1: the radius r is what scales
    diameter = (lambda d: 2 * _length((d - 1) // 2, scale) + 1 if d > 1 else d)
    people = bg.people if bg.people is None else replace(
        bg.people, motion_dilation=_length(bg.people.motion_dilation, scale),
        dilation=_length(bg.people.dilation, scale),
        edge_min_pixels=_length(bg.people.edge_min_pixels, scale))
    background = replace(bg, mask_dilation=_length(bg.mask_dilation, scale),
                         open_size=diameter(bg.open_size), close_size=diameter(bg.close_size),
                         people=people)
    det = config.detector
    detector = replace(det, edge_min_pixels=_length(det.edge_min_pixels, scale),
                       edge_neighbourhood=_length(det.edge_neighbourhood, scale))
    return replace(config, background=background, detector=detector)


def _reported(track: TrackEstimate, update) -> TrackEstimate:
    """``track`` (the target's own posterior, as the track management read it) with the
    estimate of the filter's ``update`` (a ``TrackUpdate``): where the estimate carries the
    spatial-exclusion prior (``update.own`` set) a copy with its mean, covariance and
    weights, else ``track`` itself."""
    if update.own is None:
        return track
    return replace(track, mean=update.mean, covariance=update.covariance,
                   particles=update.particles, weights=update.weights)


class Tracker:
    """Tracks people across frames with the configured algorithm.

    Args:
        calibration: the room (cameras and floor bounds) at the size of the images given
            to :meth:`step`; the tracker keeps its cameras at the working size
            (``config.working_pixels``) in :attr:`calibration` and resizes the images.
        config: tracker parameters.
        rng: random generator; default ``np.random.default_rng(config.seed)``. One draw
            from it seeds the tracks' own streams (:meth:`_stream`); the joint filter
            draws from it directly.
        measurement: optional measurement model (default: the real
            :class:`~mbtrack_ros.core.likelihood.MeasurementModel` built from ``config``).
    """

    def __init__(self, calibration: RoomCalibration, config: TrackerConfig | None = None, *,
                 rng: np.random.Generator | None = None, measurement=None) -> None:
        self.config = config or TrackerConfig()
        #: camera name -> (height, width) of the images given to step()
        self.input_sizes = {n: (c.height, c.width) for n, c in calibration.cameras.items()}
        calibration = self.config.working_calibration(calibration)
        self.calibration = calibration  # the cameras at the size the tracker works at
        self._resize = {n for n, c in calibration.cameras.items()
                        if (c.height, c.width) != self.input_sizes[n]}
        scale = length_scale(calibration)
        self.rng = rng if rng is not None else np.random.default_rng(self.config.seed)
        # every track draws from a stream of its own (see _stream), seeded from this
        self._entropy = int(self.rng.integers(2 ** 63))
        try:
            self.filter: TrackingFilter = make_filter(self.config.algorithm, calibration,
                                                      self.config)
        except FilterError as err:
            raise TrackerError(str(err)) from err
        if measurement is None:
            from mbtrack_ros.core.likelihood import MeasurementModel
            likelihood = self.config.likelihood_config()
            if scale != 1.0:  # an area given at 320 x 240: scales with the square
                likelihood = replace(likelihood, min_visible_pixels=max(1, _length(
                    likelihood.min_visible_pixels, scale * scale)))
            measurement = MeasurementModel(calibration, likelihood)
        self.measurement = measurement
        self._next_id = 1
        self._last_stamp: int | None = None
        self._search_pending = False  # step(search=False) left the detection search
        self._steps = 0  # frame sets stepped since the start or reset (detection_every)
        self._heights: dict[int, float] = {}
        self._models: dict[int, object] = {}
        self.detection = None
        if self.config.detection:
            from mbtrack_ros.core.detection.manager import AutoDetection
            self.detection = AutoDetection(calibration, self.config.detection_config(scale),
                                           sigma=float(self.config.sigma))
        self.illumination = None
        if self.detection is not None:   # the background model is the reference
            from mbtrack_ros.core.detection.illumination import IlluminationNormaliser
            self.illumination = IlluminationNormaliser(self.detection.background)

    @property
    def track_ids(self) -> list[int]:
        """Ids of the live tracks, in creation order."""
        return self.filter.track_ids()

    @property
    def models(self) -> dict[int, object]:
        """Appearance model (PersonModel) of every live track by id (a copy of the mapping)."""
        return dict(self._models)

    @property
    def last_stamp_ns(self) -> int | None:
        return self._last_stamp

    def add_track(self, model, state: np.ndarray, stamp_ns: int,
                  track_id: int | None = None) -> int:
        """Start a track for ``model`` at ``state`` (6,) observed at ``stamp_ns``
        (``track_id``: restart a released track's id, e.g. its person re-found).

        If the tracker has already processed a later or earlier frame, the state is moved to
        the tracker's current time with its own velocity (constant-velocity extrapolation),
        so that the next :meth:`step` predicts it over the right interval.

        Returns:
            the track id (1, 2, ...; a new one unless ``track_id`` is given).
        """
        s = np.asarray(state, dtype=np.float64).reshape(-1)
        if s.shape != (STATE_DIM,) or not np.all(np.isfinite(s)):
            raise TrackerError(f'a track state must be {STATE_DIM} finite numbers')
        stamp_ns = int(stamp_ns)
        if self._last_stamp is None:
            self._last_stamp = stamp_ns
        elif stamp_ns != self._last_stamp:
            s = s.copy()
            s[[X, Y]] += s[[VX, VY]] * (self._last_stamp - stamp_ns) / 1e9
        reused = track_id is not None
        if reused and (int(track_id) in self._models or not 0 < int(track_id) < self._next_id):
            raise TrackerError(f'track id {track_id} is live or was never issued')
        track_id = int(track_id) if reused else self._next_id
        try:
            self.filter.add(track_id, model, s, self._stream(s, stamp_ns))
        except FilterError as err:
            raise TrackerError(str(err)) from err
        if not reused:
            self._next_id += 1
        self._heights[track_id] = float(getattr(model, 'height', float('nan')))
        self._models[track_id] = model
        if self.detection is not None:
            self.detection.register(track_id, stamp_ns)
        return track_id

    def _stream(self, state: np.ndarray, stamp_ns: int) -> np.random.Generator:
        """The random generator of a track started (or restarted) at ``state`` (6,) at
        ``stamp_ns``: seeded by the tracker's seed, the stamp and the floor place (mm)
        only, not by the track's id, which depends on how many tracks were born before.
        A track's particles then do not depend on how many other tracks there are or
        what they drew, so a change that touches one track (a birth a frame later, a
        release elsewhere in the room) leaves the draws of the others as they were; with
        one shared generator it would reorder every later draw of every track."""
        key = tuple(int(v) % 2 ** 64 for v in (stamp_ns, round(float(state[X]) * 1000),
                                                round(float(state[Y]) * 1000)))
        return np.random.default_rng(np.random.SeedSequence(self._entropy, spawn_key=key))

    def remove_track(self, track_id: int) -> None:
        """End a track; its id is not reused."""
        try:
            self.filter.remove(track_id)
        except FilterError as err:
            raise TrackerError(str(err)) from err
        self._heights.pop(track_id, None)
        self._models.pop(track_id, None)

    def relocate_track(self, track_id: int, state: np.ndarray) -> None:
        """Restart the particles of a live track at ``state`` (6,) of the current frame,
        keeping its id and model (a track that drifted off its person, re-found by the
        detection)."""
        s = np.asarray(state, dtype=np.float64).reshape(-1)
        if s.shape != (STATE_DIM,) or not np.all(np.isfinite(s)):
            raise TrackerError(f'a track state must be {STATE_DIM} finite numbers')
        if track_id not in self._models:
            raise TrackerError(f'no track {track_id}')
        model = self._models[track_id]
        try:
            self.filter.remove(track_id)
            self.filter.add(track_id, model, s, self._stream(s, self._last_stamp or 0))
        except FilterError as err:
            raise TrackerError(str(err)) from err

    def reset(self) -> None:
        """Forget all tracks and the time base (ids keep increasing)."""
        self.filter.reset()
        self._heights.clear()
        self._models.clear()
        if self.detection is not None:
            self.detection.reset()
        if self.illumination is not None:
            self.illumination.reset()
        self._last_stamp = None
        self._search_pending = False
        self._steps = 0

    @property
    def resized_cameras(self) -> dict[str, Camera]:
        """Camera name -> working camera, of the cameras whose input images are larger
        than the working size (:meth:`working_images` resizes theirs; a reader may deliver
        them at this size instead)."""
        return {n: self.calibration.cameras[n] for n in sorted(self._resize)}

    def working_images(self, images: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """``images`` at the working size: those at a camera's input size are resized
        (area averaging, ``Camera.fit``), any other is passed on as it is (the likelihood
        refuses a wrong size). :meth:`step` calls it; a reader may deliver them resized
        instead (``RecordingReader.decode_to``)."""
        if not self._resize:
            return images
        cams = self.calibration.cameras
        return {n: cams[n].fit(im) if n in self._resize and im.shape[:2]
                == self.input_sizes[n] else im for n, im in images.items()}

    def step(self, stamp_ns: int, images: dict[str, np.ndarray], *,
             search: bool = True, stamps: dict[str, int] | None = None) -> FrameResult:
        """Predict all tracks to ``stamp_ns`` and update them with ``images``.

        With automatic detection the step also releases tracks and updates existence and
        visibility (001), then searches for new people (003 §4.1). People found are added
        as tracks from the next frame on, so the search does not change this frame's
        result: with ``search=False`` it is left for :meth:`search`, which a node calls
        after publishing the result (lower latency, the same outputs); a search left
        pending runs at the start of the next step. The frame's foreground (003 §4.2) does
        not depend on the filter: it runs on the detection's worker thread while the filter
        runs (:meth:`AutoDetection.start_foreground`; the same outputs).

        With ``config.pipeline_search`` the search of this frame runs on that worker while
        the next frame is filtered (:meth:`AutoDetection.start_search`), and its people
        become tracks in the next :meth:`search` (after the next frame's result,
        :meth:`AutoDetection.finish_search`): one frame later than without, at a fixed
        point, so the outputs do not depend on the threads' timing.

        Args:
            stamp_ns: frame stamp, integer nanoseconds; must not go backwards.
            images: ``(H, W, 3) uint8`` RGB images by camera name, at the size of the
                calibration given to the tracker (resized here once to the working size,
                :meth:`working_images`).
            search: run the detection search now (default) or leave it for :meth:`search`.
            stamps: camera name -> capture time of its image, integer ns (unsynchronised
                cameras; default: every image at ``stamp_ns``). The tracks are at
                ``stamp_ns`` (the latest capture of the set, by convention); each camera's
                update evaluates the particles predicted to its own capture time
                (:meth:`MeasurementModel.set_capture_offsets`).

        Returns:
            :class:`~mbtrack_ros.core.state.FrameResult` with one estimate per track.
        """
        self.search()  # a search left pending by the previous step
        stamp_ns = int(stamp_ns)
        if self._last_stamp is not None and stamp_ns < self._last_stamp:
            raise TrackerError(f'stamp {stamp_ns} ns is before the previous frame '
                               f'{self._last_stamp} ns; reset the tracker')
        dt = 0.0 if self._last_stamp is None else (stamp_ns - self._last_stamp) / 1e9
        t0 = time.perf_counter()
        images = self.working_images(images)   # the one resize of every frame
        if self.illumination is not None:   # global colour gains undone (illumination.py)
            images = self.illumination.normalise(images)
        detect = self.detection is not None \
            and self._steps % int(self.config.detection_every) == 0
        if detect:  # the foreground runs on a worker during the filter
            self.detection.start_foreground(images)
        try:
            seen = images if self.detection is None else self.detection.tracking_images(images)
            self.measurement.set_images(seen)
            if stamps and hasattr(self.measurement, 'set_capture_offsets'):
                self.measurement.set_capture_offsets(
                    {n: (int(stamps[n]) - stamp_ns) / 1e9 for n in seen if n in stamps})
            if detect:   # the coverage term joins the frame's foreground when it needs it
                # the bootstrap's possible people are foreground by guess, not observed:
                # they count as the coverage at which the existence evidence is neutral
                self.measurement.set_foreground(
                    self.detection.started_foreground,
                    undecided=self.detection.started_possible,
                    neutral=self.detection.config.release.min_coverage)
            t1 = time.perf_counter()
            updates = self.filter.step(dt, self.measurement, seen, self.rng)
            t2 = time.perf_counter()
        except BaseException:
            if detect:
                self.detection.abandon()
            raise
        self._last_stamp = stamp_ns
        self._steps += 1
        # the track management reads each target's own posterior (TrackUpdate.own): the
        # spatial-exclusion prior corrects the reported estimate only, as it leaves the
        # particles alone, so the tracks the filter carries on, their release, existence,
        # re-finding and appearance models do not depend on it
        tracks = []
        for tid in sorted(updates):
            u = updates[tid].own or updates[tid]
            tracks.append(TrackEstimate(
                track_id=tid, mean=u.mean, covariance=u.covariance,
                height=self._heights.get(tid, float('nan')),
                visible_fraction=dict(u.visible_fraction), existence=1.0,
                particles=u.particles, weights=u.weights,
                width=float(getattr(self._models.get(tid), 'width', 0.5))))
        timings = {'prepare': t1 - t0}
        timings.update(self.filter.timings)
        timings['filter'] = t2 - t1
        ended: list[int] = []
        released: list[int] = []
        if self.detection is not None and not detect:  # detection_every: the last decisions
            self.detection.carry(tracks)
            tracks = [t for t in tracks if self.detection.reported(t.track_id)]
        elif self.detection is not None:  # 003 §4: release; 001: existence and visibility
            frame_bins = getattr(self.measurement, 'frame_bins', None)
            released = self.detection.update(stamp_ns, images, tracks, self._models,
                                             bins=frame_bins() if frame_bins else None)
            for tid in released:
                self.remove_track(tid)
            for t in tracks:   # a lagging track catches up (AutoDetectionConfig.reach_radius)
                if t.track_id in self.detection.reach_moves and t.track_id not in released:
                    state = t.mean.copy()
                    state[[X, Y]] = self.detection.reach_moves[t.track_id]
                    state[SIT] = float(state[SIT] >= 0.5)      # the mean holds p(sitting)
                    self.relocate_track(t.track_id, state)
            tracks = [t for t in tracks
                      if t.track_id not in released and self.detection.reported(t.track_id)]
            ended = self.detection.finished(released)   # lost ones end when they cannot return
            self._search_pending = True
            if search:
                self.search()
            timings.update(self.detection.timings)
        tracks = [_reported(t, updates[t.track_id]) for t in tracks]
        timings['total'] = time.perf_counter() - t0
        return FrameResult(stamp_ns=stamp_ns, tracks=tracks, ended=ended, timings=timings,
                           released=released)

    def search(self) -> list[int]:
        """The detection search and acquisition of the last step (003 §4.1-4.2), if pending:
        new people become tracks, re-found ones move their track. Returns the ids of the
        tracks started or moved.

        With ``pipeline_search``: the people found by the previous step's search, which ran
        on the detection's worker during this step's filter, become tracks, then this step's
        search starts on the worker (its people come with the next call)."""
        if not self._search_pending or self.detection is None:
            return []
        self._search_pending = False
        if not self.config.pipeline_search:
            return self._place(self.detection.search(), self._last_stamp)
        found_stamp, births = self.detection.finish_search()
        changed = self._place(births, found_stamp)
        self.detection.start_search(born=[(self._now(b.state, found_stamp), b.model.shape)
                                          for b in births])
        return changed

    def _place(self, births: list, stamp_ns: int | None) -> list[int]:
        """Start the tracks of ``births`` found in the frame set at ``stamp_ns`` and move
        the re-found ones (their states moved to the current time with their velocity);
        returns the ids started or moved."""
        changed = []
        for birth in births:
            if birth.track_id is not None and birth.track_id in self._models:
                self.relocate_track(birth.track_id, self._now(birth.state, stamp_ns))
                changed.append(int(birth.track_id))
            else:
                changed.append(self.add_track(birth.model, birth.state, stamp_ns,
                                              track_id=birth.track_id))
        return changed

    def _now(self, state: np.ndarray, stamp_ns: int | None) -> np.ndarray:
        """A state (6,) observed at ``stamp_ns`` moved to the last frame's time with its own
        velocity (constant-velocity extrapolation, as :meth:`add_track`)."""
        if stamp_ns is None or stamp_ns == self._last_stamp:
            return state
        s = np.array(state, dtype=np.float64)
        s[[X, Y]] += s[[VX, VY]] * (self._last_stamp - stamp_ns) / 1e9
        return s
