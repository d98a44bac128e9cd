"""Errors of the evaluation subpackage."""
from __future__ import annotations

__all__ = ['EvaluationError']


class EvaluationError(ValueError):
    """Inputs that cannot be scored: empty ground truth, duplicate rows, bad particle file."""
