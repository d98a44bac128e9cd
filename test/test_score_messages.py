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


def test_remote_scorer_waits_until_the_timeout_then_backs_off(rng):
    """The fusion tracker's side: an answer in time is taken; a camera that misses the
    timeout is not waited for during the next 1, 2, 4, ... requests (an answer there
    already is taken), and one answer in time resets the back-off; a late answer (to an
    earlier request) is dropped."""
    import time

    from mbtrack_ros.nodes.fusion_input import RemoteScorer

    sent, warned = [], []
    scorer = RemoteScorer('cam0', sent.append, 0.05, lambda cause, text: warned.append(text))
    scores = CameraScores(rng.random(3), rng.random(1), rng.random(3), rng.random(3))

    def answer(k=-1):
        seq, _, _ = read_request(sent[k])
        scorer.on_answer(scores_message(seq, 0, scores))

    request = _request(rng, n=3, k=1, v=1)
    wait = scorer(request)
    answer()
    np.testing.assert_array_equal(wait().loglik, scores.loglik)        # in time
    t = time.monotonic()
    assert scorer(request)() is None and time.monotonic() - t >= 0.05  # missed: waited
    assert warned and scorer.missed == 1
    wait = scorer(request)                      # backing off: 1 request not waited for
    t = time.monotonic()
    assert wait() is None and time.monotonic() - t < 0.04
    assert scorer(request)() is None and scorer.missed == 2            # waited, missed
    for _ in range(2):                                                 # back-off 2
        wait = scorer(request)
        answer(-2)                                                     # a late answer
        assert wait() is None
    wait = scorer(request)                      # waited again, answered: back-off reset
    answer()
    assert wait() is not None
    assert scorer(request)() is None and scorer.missed == 3
    wait = scorer(request)                      # back-off 1, but the answer is there
    answer()
    assert wait() is not None and scorer.answered == 3 and scorer.asked == len(sent)


def test_remote_scorer_refuses_scores_that_do_not_fit_the_request(rng):
    """An answer of another shape than the request's particles and targets, or with a
    non-finite log-likelihood, is refused at once (counted, warned): no scores, so the
    tracker scores the camera itself; finite scores of the right shape (NaN cover is
    'no coverage term') are taken."""
    from mbtrack_ros.nodes.fusion_input import RemoteScorer

    sent, warned = [], []
    scorer = RemoteScorer('cam0', sent.append, 5.0, lambda cause, text: warned.append(text))
    request = _request(rng, n=3, k=1, v=1)
    good = CameraScores(rng.random(3), rng.random(1), rng.random(3), np.full(3, np.nan))
    nan = replace(good, loglik=np.array([0.1, np.nan, 0.2]))
    for bad in (CameraScores(rng.random(4), rng.random(1), rng.random(4), rng.random(4)),
                CameraScores(rng.random(3), rng.random(2), rng.random(3), rng.random(3)),
                nan):
        wait = scorer(request)
        scorer.on_answer(scores_message(read_request(sent[-1])[0], 0, bad))
        assert wait() is None                     # at once: not after the 5 s timeout
    assert scorer.refused == 3 and len(warned) == 3 and scorer.missed == 0
    wait = scorer(request)
    scorer.on_answer(scores_message(read_request(sent[-1])[0], 0, good))
    np.testing.assert_array_equal(wait().loglik, good.loglik)


def test_remote_scorer_neither_asks_nor_waits_for_a_camera_node_not_matched_yet(rng):
    """While the camera node's end points are not matched (not up, or not discovered),
    no request goes out and none is waited for, without a miss or a back-off; the first
    request once it is matched is waited for and its answer taken."""
    import time

    from mbtrack_ros.nodes.fusion_input import RemoteScorer

    sent, warned, matched = [], [], [False]
    scorer = RemoteScorer('cam0', sent.append, 5.0, lambda cause, text: warned.append(text),
                          ready=lambda: matched[0])
    request = _request(rng, n=3, k=1, v=1)
    t = time.monotonic()
    for _ in range(3):
        assert scorer(request)() is None
    assert time.monotonic() - t < 1.0               # not the 5 s timeout
    assert not sent and not warned and scorer.missed == 0 and scorer.unready == 3
    matched[0] = True
    wait = scorer(request)
    scores = CameraScores(rng.random(3), rng.random(1), rng.random(3), rng.random(3))
    scorer.on_answer(scores_message(read_request(sent[-1])[0], 0, scores))
    np.testing.assert_array_equal(wait().loglik, scores.loglik)
    assert scorer.asked == 1 and scorer.answered == 1
