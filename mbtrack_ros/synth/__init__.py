"""Synthetic multi-camera smart-room recordings with ground truth (``mbtrack synth``).

An independent renderer (ray-cast room, articulated ellipsoid bodies): it does not use the
tracker's shape or appearance models. See README_SYNTH.md.
"""
from __future__ import annotations

from mbtrack_ros.synth.errors import SynthError
from mbtrack_ros.synth.generator import (EPOCH_NS, SynthFrame, Synthesizer, generate,
                                         iter_frames, render_view, visible_threshold)
from mbtrack_ros.synth.presets import PRESETS, Preset, get_preset

__all__ = ['EPOCH_NS', 'PRESETS', 'Preset', 'SynthError', 'SynthFrame', 'Synthesizer',
           'generate', 'get_preset', 'iter_frames', 'render_view', 'visible_threshold']
