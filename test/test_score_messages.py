"""The score requests and answers between a fusion tracker and its camera nodes: what is
sent is what is read, and a message that does not parse is refused in one line."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mbtrack_ros.core.likelihood import CameraRequest, CameraScores
from mbtrack_ros.nodes.score_messages import (
    ScoreMessageError, read_request, read_scores, request_message, scores_message)


def _request(rng, n=7, k=2, v=3) -> CameraRequest:
    return CameraRequest(rng.random((n, 6)), rng.integers(0, k, n), rng.random(n),
                         rng.random(n) + 1.5, rng.random(n), 0.45, rng.random((k, v)),
                         np.array([v, 1] * k)[:k], rng.random((k, v, 1536)), False, 0.03,
                         0.15, 2, 20, True, 0.3)


@pytest.mark.parametrize('versions', [True, False])
def test_request_round_trip(rng, versions):
    """With versions only the key views of ``key_targets`` travel; without, every
    target's, under versions of their own."""
    sent = _request(rng)
    if versions:
        sent = replace(sent, key=sent.key[[1]], versions=np.array([5, 9]),
                       key_targets=np.array([1]), separable=True, coverage=False)
    seq, stamp, got = read_request(request_message(41, 1_700_000_000_123_456_789, sent))
    assert (seq, stamp) == (41, 1_700_000_000_123_456_789)
    for name in ('states', 'target', 'prior', 'heights', 'widths', 'view_angles', 'n_views',
                 'key'):
        np.testing.assert_array_equal(getattr(got, name), getattr(sent, name))
    if versions:
        assert got.versions.tolist() == [5, 9] and got.key_targets.tolist() == [1]
    else:
        assert got.versions.tolist() == [-1, -2] and got.key_targets.tolist() == [0, 1]
    for name in ('chair', 'separable', 'two_sigma_sq', 'd_occ', 'row_step', 'min_visible',
                 'coverage', 'neutral'):
        assert getattr(got, name) == getattr(sent, name), name


def test_scores_round_trip(rng):
    sent = CameraScores(rng.random(5), rng.random(2), rng.random(5), rng.random(5))
    sent.cover[1] = np.nan
    seq, stamp, got = read_scores(scores_message(3, 99, sent))
    assert (seq, stamp) == (3, 99)
    for name in ('loglik', 'visible', 'inside', 'cover'):
        np.testing.assert_array_equal(getattr(got, name), getattr(sent, name))
    assert read_scores(scores_message(4, 100, None)) == (4, 100, None)


def test_malformed_messages_are_refused(rng):
    msg = request_message(1, 2, _request(rng))
    short = type(msg)()
    short.data = bytes(msg.data)[:-8]
    with pytest.raises(ScoreMessageError, match='expected'):
        read_request(short)
    with pytest.raises(ScoreMessageError, match='not a score request'):
        read_request(scores_message(1, 2, None))
    with pytest.raises(ScoreMessageError, match='not a score answer'):
        read_scores(msg)
    empty = type(msg)()
    with pytest.raises(ScoreMessageError, match='0 bytes'):
        read_scores(empty)
