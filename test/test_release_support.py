"""The release's support verdict pools every camera's coverage evidence (release.py module
docstring): no camera, the top-down one included, decides alone."""
from __future__ import annotations

import numpy as np

from mbtrack_ros.core.camera import Camera, RoomCalibration, look_at
from mbtrack_ros.core.detection.detector import FrameEvidence, is_ceiling
from mbtrack_ros.core.detection.release import ReleaseConfig, Releaser, blob_coverage
from mbtrack_ros.core.existence import coverage_log_ratio
from mbtrack_ros.core.shape import BodyShape, rasterize

W, H = 160, 120


def make_room() -> RoomCalibration:
    """6 x 5 m room, four upper-corner cameras and a ceiling camera, no exits."""
    cams = {}
    for k, (x, y) in enumerate([(0.1, 0.1), (5.9, 0.1), (5.9, 4.9), (0.1, 4.9)]):
        R, t = look_at((x, y, 2.6), (3.0, 2.5, 0.8))
        cams[f'cam{k}'] = Camera(f'cam{k}', W, H, [[90, 0, 79.5], [0, 90, 59.5], [0, 0, 1]],
                                 [-0.1, 0.01, 0, 0, 0], R, t)
    R, t = look_at((3.0, 2.5, 2.75), (3.0, 2.5, 0.0), up=(0, 1, 0))
    cams['cam4'] = Camera('cam4', W, H, [[60, 0, 79.5], [0, 60, 59.5], [0, 0, 1]],
                          [0] * 5, R, t)
    return RoomCalibration(cams, (0.3, 0.3, 5.7, 4.7))


def _support(rel: Releaser, calib: RoomCalibration, states: np.ndarray,
             fg: dict[str, np.ndarray]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    heights = np.full(len(states), 1.75)
    sils = {n: rasterize(c, states, BodyShape()) for n, c in calib.cameras.items()}
    image = np.zeros((H, W, 3), np.uint8)
    ev = {n: FrameEvidence(image, m) for n, m in fg.items()}
    return rel.support(ev, sils, states, heights)


def test_the_support_verdict_is_the_sign_of_the_pooled_coverage_evidence():
    """Brute force: per track and camera the coverage counted pixel by pixel from the
    silhouette mask (the top-down camera: its cylinder blob, doubled and clipped to 1),
    cameras that see too few pixels left out; the verdict is the sign of the existence
    process's coverage log-ratio (neutral at min_coverage), whatever the cameras."""
    calib = make_room()
    cfg = ReleaseConfig(spare_support=0.0)        # the coverage verdict alone
    rel = Releaser(calib, cfg)
    rng = np.random.default_rng(3)
    states = np.zeros((6, 6))
    states[:, 0] = rng.uniform(0.8, 5.2, 6)
    states[:, 1] = rng.uniform(0.8, 4.2, 6)
    min_area = cfg.min_area * W * H / (320.0 * 240.0)
    for _ in range(20):
        fg = {}
        for n in calib.cameras:     # blocks of foreground of random density
            coarse = rng.random((H // 8, W // 8)) < rng.uniform(0.05, 0.6)
            fg[n] = np.kron(coarse, np.ones((8, 8), bool))
        supported, coverage = _support(rel, calib, states, fg)
        assert rel.kept.all()     # neither spare (off) nor in a doorway (no exits)
        for k in range(len(states)):
            cov = {}
            for n, cam in calib.cameras.items():
                if is_ceiling(cam):
                    c, area = blob_coverage(cam, fg[n], states[k:k + 1, :2], np.array([1.75]))
                    c, area = min(2.0 * c[0], 1.0), area[0]
                else:
                    mask = rasterize(cam, states[k:k + 1], BodyShape()).mask(0) > 0
                    area = mask.sum()
                    c = fg[n][mask].mean() if area else 0.0
                if area >= min_area:
                    cov[n] = c
                    assert np.isclose(coverage[n][k], c)
                else:
                    assert np.isnan(coverage[n][k])
            ratio = coverage_log_ratio(cov, {}, 1.0, neutral=cfg.min_coverage)
            if abs(ratio) > 1e-9:
                assert supported[k] == (ratio > 0), (k, cov)


def test_a_person_the_top_down_camera_covers_poorly_is_supported_by_the_side_views():
    """A person sitting by a wall fills little of the top-down camera's cylinder blob and
    most of the side views' silhouettes: supported. The converse (only the top-down
    camera's blob covered, four empty side views) is not."""
    calib = make_room()
    rel = Releaser(calib, ReleaseConfig(spare_support=0.0))
    states = np.array([[0.7, 2.5, 0, 0, 0, 0]])
    sils = {n: rasterize(c, states, BodyShape()) for n, c in calib.cameras.items()}
    side = {n: (sils[n].mask(0) > 0) if not is_ceiling(c) else np.zeros((H, W), bool)
            for n, c in calib.cameras.items()}
    supported, coverage = _support(rel, calib, states, side)
    assert coverage['cam4'][0] == 0.0 and supported[0]
    top = {n: np.ones((H, W), bool) if is_ceiling(c) else np.zeros((H, W), bool)
           for n, c in calib.cameras.items()}
    supported, coverage = _support(rel, calib, states, top)
    assert coverage['cam4'][0] == 1.0 and not supported[0]
