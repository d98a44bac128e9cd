"""Shared by the diagnostics that read ``detection_eval.py run`` outputs: that module, and
the OUT REC pairs of a command line."""
import importlib.util
import sys
from pathlib import Path

_spec = importlib.util.spec_from_file_location(
    'detection_eval', Path(__file__).resolve().parents[1] / 'detection_eval.py')
detection_eval = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(detection_eval)


def pairs(usage: str) -> list[tuple[Path, Path]]:
    """The (OUT, REC) pairs of ``sys.argv``; exits with ``usage`` when there are none."""
    args = [Path(a) for a in sys.argv[1:]]
    if not args or len(args) % 2:
        sys.exit(f'usage: {usage}')
    return list(zip(args[::2], args[1::2]))
