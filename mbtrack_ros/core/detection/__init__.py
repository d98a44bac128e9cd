"""Automatic target detection, model acquisition and track release (003 §4), and the
visibility/existence auxiliary processes (001 §3) in :mod:`mbtrack_ros.core.existence`.

* :mod:`.background` - per-camera Y-Cb-Cr background model and foreground masks, with
  *not yet known* places for rooms that are never empty and the border test that learns
  ghosts (places revealed by people who were learnt into the model);
* :mod:`.people` - a background-independent multi-view people cue (motion in several
  views, contour and colour symmetry) that marks those places at the online bootstrap;
* :mod:`.features` - single-view detection features: foreground coverage, contour
  likelihood (003 Eq. 5), upper-body colour symmetry;
* :mod:`.detector` - coarse-to-fine grid search over the floor, multi-camera fusion,
  non-maximum suppression and confirmation over consecutive frames;
* :mod:`.acquisition` - key-view appearance model of a newly detected person;
* :mod:`.release` - termination of tracks without foreground support;
* :mod:`.config` - :class:`~.config.AutoDetectionConfig`, the pipeline's parameters;
* :mod:`.association` - what a confirmed detection is: a birth, a track's person re-found
  (move), a lost track's person (reuse) or nothing (drop);
* :mod:`.likeness` - the appearance likelihood ratio of two models (same person or not),
  calibrated on the tracks;
* :mod:`.deleter` - existence evidence of the tracks, duplicates, exits;
* :mod:`.manager` - :class:`~.manager.AutoDetection`, the per-frame pipeline the tracker
  calls when ``TrackerConfig.detection`` is set.
"""
from __future__ import annotations

__all__ = ['DetectionError']


class DetectionError(ValueError):
    """Bad input to the detection subpackage (image size, configuration, missing model)."""
