"""Errors of the synthetic-recording subpackage."""
from __future__ import annotations

__all__ = ['SynthError']


class SynthError(ValueError):
    """Bad input to the renderer or the recording generator (one-line message)."""
