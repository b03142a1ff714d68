"""The accumulator on a thread of its own (offline analyze): the same sums, errors kept."""

import threading

import numpy as np
from numpy.testing import assert_array_equal
import pytest

from imu_allan.core.allan.accumulator import AllanAccumulator
from imu_allan.errors import InputError
from imu_allan.pipeline.feed import BackgroundAccumulator
from imu_allan.pipeline.hygiene import SessionConfig
from imu_allan.pipeline.session import Session


def _record(seed: int, n: int) -> tuple:
    rng = np.random.default_rng(seed)
    y = rng.standard_normal((n, 6)) * 1e-3 + np.cumsum(rng.standard_normal((n, 6)),
                                                       axis=0) * 1e-6
    cuts = np.sort(rng.choice(np.arange(1, n), 30, replace=False))
    return y, cuts


def _feed(acc, y, cuts) -> None:
    for k, block in enumerate(np.split(y, cuts)):
        acc.add(block)
        if k == 11:
            acc.break_segment()


def test_background_feed_gives_bit_identical_sums():
    # The same calls in the same order on another thread: not a bit may differ.
    y, cuts = _record(31, 200_000)
    inline = AllanAccumulator(6, 200.0, exact_max_m=1024)
    _feed(inline, y, cuts)
    feed = BackgroundAccumulator(AllanAccumulator(6, 200.0, exact_max_m=1024))
    _feed(feed, y, cuts)
    assert feed.n_samples == inline.n_samples          # read through: waits for the queue
    a, b = inline.curve(), feed.curve()
    assert_array_equal(a.avar, b.avar)
    assert_array_equal(a.n_terms, b.n_terms)
    feed.rate_hz = 100.0                               # set through, after the queue
    plain = feed.close()
    assert isinstance(plain, AllanAccumulator) and plain.rate_hz == 100.0


def test_background_feed_raises_the_workers_error_on_the_next_call():
    feed = BackgroundAccumulator(AllanAccumulator(6, 200.0))
    feed.add(np.zeros((10, 6)))
    feed.add(np.zeros((10, 5)))                        # wrong shape: fails on the thread
    with pytest.raises(InputError, match='shape'):
        feed.sync()
    feed.add(np.ones((10, 6)))                         # goes on after the error was seen
    assert feed.close().n_samples == 20


def test_session_in_background_equals_inline_and_stops_its_thread():
    y, cuts = _record(32, 120_000)
    stamps = 1_700_000_000_000_000_000 + np.arange(y.shape[0], dtype=np.int64) * 5_000_000
    curves = []
    before = threading.active_count()
    for background in (False, True):
        session = Session(SessionConfig(rate_hz=200.0, background_accumulator=background))
        for t, block in zip(np.split(stamps, cuts), np.split(y, cuts)):
            session.add(t, block)
        session.flush()
        assert isinstance(session.acc, AllanAccumulator)   # plain again after flush
        curves.append(session.curve())
    assert threading.active_count() == before
    assert_array_equal(curves[0].avar, curves[1].avar)
    assert_array_equal(curves[0].edf, curves[1].edf)
