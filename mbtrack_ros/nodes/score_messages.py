"""The fusion tracker's score requests to the camera nodes and their answers.

A fusion tracker (``tracker_node`` with ``input_mode: foreground``) asks each camera node to
score the frame set's particles in its camera (the camera's share of the HJS likelihood,
:meth:`~mbtrack_ros.core.detection.camera_stage.CameraStage.score`): on
``<camera namespace>/working/score_request`` it sends a
:class:`~mbtrack_ros.core.likelihood.CameraRequest`, and the camera node answers on
``<camera namespace>/working/scores`` with the :class:`~mbtrack_ros.core.likelihood
.CameraScores`. Both travel as ``std_msgs/UInt8MultiArray`` (no ``layout``) whose bytes are,
little endian::

    request:  b'MBSQ', version u16 (1), flags u16 (1 separable, 2 coverage), seq u32,
              stamp i64 (ns, the camera's frame), P u32 (particles), K u32 (targets),
              V u32 (key views per target), M u32 (targets whose key views are sent),
              row_step u32, min_visible u32, chair f64, two_sigma_sq f64, d_occ f64,
              neutral f64; then states (P, 6) f64, target (P,) i64, prior (P,) f64,
              heights (P,) f64, widths (P,) f64, view_angles (K, V) f64, n_views (K,) i64,
              versions (K,) i64 (of each target's key views), key_targets (M,) i64 and
              their key views (M, V, 1536) f64
    answer:   b'MBSR', version u16 (1), flags u16 (1: no scores, the camera has no such
              frame or lacks key views of earlier requests), seq u32, stamp i64, P u32,
              K u32; then loglik (P,), visible (K,), inside (P,), cover (P,) f64

``seq`` pairs an answer with its request. The decoders raise :class:`ScoreMessageError`
(one line) for a message that does not parse.
"""
from __future__ import annotations

import struct

import numpy as np
from std_msgs.msg import UInt8MultiArray

from mbtrack_ros.core.likelihood import CameraRequest, CameraScores

__all__ = ['ScoreMessageError', 'read_request', 'read_scores', 'request_message',
           'scores_message']

_REQUEST = struct.Struct('<4sHHIqIIIIIIdddd')
_ANSWER = struct.Struct('<4sHHIqII')
_VERSION = 1
_SEPARABLE, _COVERAGE = 1, 2
_NONE = 1
_HIST = 1536
MAX_PARTICLES = 1_000_000   # bounded work and memory per message
MAX_VIEWS = 4096            # targets x key views


class ScoreMessageError(ValueError):
    """A score request or answer that does not parse."""


def _bytes(msg) -> memoryview:
    return memoryview(msg.data).cast('B') if not isinstance(msg.data, (bytes, bytearray)) \
        else memoryview(msg.data)


def request_message(seq: int, stamp_ns: int, request: CameraRequest) -> UInt8MultiArray:
    """A request as a ``std_msgs/UInt8MultiArray`` (module docstring); without
    ``versions`` every target's key views go, under versions of their own (-1, -2, ...)."""
    r = request
    n, k = len(r.states), len(r.n_views)
    v = int(np.shape(r.view_angles)[1]) if k else 0
    versions, targets = r.versions, r.key_targets
    if versions is None or targets is None:
        versions, targets = -1 - np.arange(k), np.arange(k)
    m = len(targets)
    flags = (_SEPARABLE if r.separable else 0) | (_COVERAGE if r.coverage else 0)
    parts = [_REQUEST.pack(b'MBSQ', _VERSION, flags, seq & 0xFFFFFFFF, int(stamp_ns), n, k, v,
                           m, int(r.row_step), int(r.min_visible), float(r.chair),
                           float(r.two_sigma_sq), float(r.d_occ), float(r.neutral))]
    for a, dtype in ((r.states, '<f8'), (r.target, '<i8'), (r.prior, '<f8'),
                     (r.heights, '<f8'), (r.widths, '<f8'), (r.view_angles, '<f8'),
                     (r.n_views, '<i8'), (versions, '<i8'), (targets, '<i8'), (r.key, '<f8')):
        parts.append(np.ascontiguousarray(a, dtype).tobytes())
    msg = UInt8MultiArray()
    msg.data = b''.join(parts)
    return msg


def read_request(msg) -> tuple[int, int, CameraRequest]:
    """(seq, stamp ns, request) of a request message (its ``versions`` and
    ``key_targets`` set); :class:`ScoreMessageError`."""
    data = _bytes(msg)
    if bytes(data[:4]) != b'MBSQ':
        raise ScoreMessageError('not a score request')
    if len(data) < _REQUEST.size:
        raise ScoreMessageError(f'score request of {len(data)} bytes')
    (magic, version, flags, seq, stamp, n, k, v, m, row_step, min_visible, chair,
     two_sigma_sq, d_occ, neutral) = _REQUEST.unpack_from(data)
    if magic != b'MBSQ' or version != _VERSION:
        raise ScoreMessageError(f'not a score request of version {_VERSION}')
    if n > MAX_PARTICLES or k * max(v, 1) > MAX_VIEWS or m > k:
        raise ScoreMessageError(f'score request too large ({n} particles, {k}x{v} views)')
    shapes = [((n, 6), '<f8'), ((n,), '<i8'), ((n,), '<f8'), ((n,), '<f8'), ((n,), '<f8'),
              ((k, v), '<f8'), ((k,), '<i8'), ((k,), '<i8'), ((m,), '<i8'),
              ((m, v, _HIST), '<f8')]
    need = _REQUEST.size + 8 * sum(int(np.prod(s)) for s, _ in shapes)
    if len(data) != need:
        raise ScoreMessageError(f'score request of {len(data)} bytes, expected {need}')
    a, at = [], _REQUEST.size
    for shape, dtype in shapes:
        size = 8 * int(np.prod(shape))
        a.append(np.frombuffer(data[at:at + size], dtype).reshape(shape))
        at += size
    return seq, stamp, CameraRequest(
        a[0], a[1], a[2], a[3], a[4], chair, a[5], a[6], a[9], bool(flags & _SEPARABLE),
        two_sigma_sq, d_occ, row_step, min_visible, bool(flags & _COVERAGE), neutral,
        versions=a[7], key_targets=a[8])


def scores_message(seq: int, stamp_ns: int, scores: CameraScores | None) -> UInt8MultiArray:
    """An answer as a ``std_msgs/UInt8MultiArray``; ``scores`` None: no scores."""
    msg = UInt8MultiArray()
    if scores is None:
        msg.data = _ANSWER.pack(b'MBSR', _VERSION, _NONE, seq & 0xFFFFFFFF, int(stamp_ns),
                                0, 0)
        return msg
    n, k = len(scores.loglik), len(scores.visible)
    msg.data = b''.join([_ANSWER.pack(b'MBSR', _VERSION, 0, seq & 0xFFFFFFFF, int(stamp_ns),
                                      n, k)]
                        + [np.ascontiguousarray(a, '<f8').tobytes() for a in (
                            scores.loglik, scores.visible, scores.inside, scores.cover)])
    return msg


def read_scores(msg) -> tuple[int, int, CameraScores | None]:
    """(seq, stamp ns, scores or None) of an answer message; :class:`ScoreMessageError`."""
    data = _bytes(msg)
    if len(data) and bytes(data[:4]) != b'MBSR':
        raise ScoreMessageError('not a score answer')
    if len(data) < _ANSWER.size:
        raise ScoreMessageError(f'score answer of {len(data)} bytes')
    magic, version, flags, seq, stamp, n, k = _ANSWER.unpack_from(data)
    if magic != b'MBSR' or version != _VERSION:
        raise ScoreMessageError(f'not a score answer of version {_VERSION}')
    if flags & _NONE:
        return seq, stamp, None
    need = _ANSWER.size + 8 * (3 * n + k)
    if len(data) != need:
        raise ScoreMessageError(f'score answer of {len(data)} bytes, expected {need}')
    a = np.frombuffer(data[_ANSWER.size:], '<f8')
    return seq, stamp, CameraScores(a[:n].copy(), a[n:n + k].copy(), a[n + k:2 * n + k].copy(),
                                    a[2 * n + k:].copy())
