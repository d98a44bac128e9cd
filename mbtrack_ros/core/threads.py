"""Per-camera work on a small thread pool.

The per-camera stages (numba kernels compiled with ``nogil=True``, OpenCV calls) release the
GIL, so the cameras of one frame can run in parallel threads with the same results as one
after the other.
"""
from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

__all__ = ['CameraThreads']

T = TypeVar('T')
R = TypeVar('R')


class CameraThreads:
    """``map(fn, items)`` on up to one thread per CPU core (the pool is created on first use;
    a single item, or a single core, runs in the caller's thread).

    Args:
        name: thread name prefix.
        workers: largest number of threads (0: one per CPU core).
    """

    def __init__(self, name: str, workers: int = 0) -> None:
        self.name = name
        self.workers = int(workers) or (os.cpu_count() or 1)
        self._pool: ThreadPoolExecutor | None = None

    def map(self, fn: Callable[[T], R], items: Iterable[T]) -> list[R]:
        items = list(items)
        if len(items) < 2 or self.workers < 2:
            return [fn(item) for item in items]
        if self._pool is None:
            self._pool = ThreadPoolExecutor(max_workers=self.workers,
                                            thread_name_prefix=self.name)
        return list(self._pool.map(fn, items))

    def close(self) -> None:
        """Stop the threads (a later :meth:`map` starts new ones)."""
        if self._pool is not None:
            self._pool.shutdown(wait=False)
            self._pool = None

    def __del__(self) -> None:
        pool = getattr(self, '_pool', None)
        if pool is not None:
            pool.shutdown(wait=False)
