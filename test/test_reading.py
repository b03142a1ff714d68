"""Tests of how a plan reads its expected widths: dispersion, present width, crossing."""

import math

import numpy as np
from numpy.testing import assert_allclose
import pytest

from imu_allan.core.plan.reading import as_read, crossing, inflated, inflation


def test_the_plan_is_inflated_by_the_fits_dispersion_only():
    # A fit as dispersed as its model allows keeps the expected widths; one with
    # J / dof = 3 widens z by about sqrt(3) (the fit's profile threshold grows so).
    assert inflation(40.0, 50) == 1.0
    assert inflation(math.nan, 50) == inflation(10.0, 0) == 1.0
    assert_allclose(inflation(150.0, 50), math.sqrt(3.0), rtol=0.06)   # F vs chi2 quantile
    assert_allclose(inflated(np.array([0.1, 0.5]), 1.0), [0.1, 0.5], rtol=1e-12)


def test_the_plan_starts_at_the_present_width_and_joins_the_expected_ones():
    lengths = np.array([1.0, 4.0, 100.0, 1e4]) * 3600.0
    expected = 0.2 * np.sqrt(lengths[0] / lengths)      # resolved: L^-1/2
    for now in (0.35, 0.12):                            # wider, or luckily narrower
        read = as_read(expected, lengths, 1.0, lengths[0], now)
        assert read[0] == pytest.approx(now, rel=1e-12)
        # The excess on the log scale shrinks as sd: (1 h / L)^(1/2).
        excess = np.arcsinh(read) / np.arcsinh(expected) - 1.0
        assert_allclose(excess, excess[0] * np.sqrt(lengths[0] / lengths), rtol=1e-9)
    # No present width (a datasheet): the expected widths, inflated.
    assert_allclose(as_read(expected, lengths, 1.5, 0.0, math.nan),
                    inflated(expected, 1.5), rtol=1e-12)


def test_crossing_interpolates_in_log_log():
    lengths = np.array([1.0, 4.0, 16.0]) * 3600.0
    widths = 0.4 * np.sqrt(lengths[0] / lengths)       # 0.4, 0.2, 0.1
    # Widths as L^-1/2: 0.15 is met at (0.4 / 0.15)^2 h.
    assert crossing(lengths, widths, 0.15) == pytest.approx((0.4 / 0.15) ** 2 * 3600.0,
                                                            rel=1e-12)
    assert crossing(lengths, widths, 0.5) == lengths[0]
    assert crossing(lengths, widths, 0.05) == math.inf
    assert crossing(lengths, np.array([math.inf, 0.2, 0.1]), 0.3) == lengths[1]
