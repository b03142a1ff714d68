"""The ADEV figure (io/plot.py): one dotted line per group of terms, N, B, K marked."""

import numpy as np
import pytest

from conftest import REPO
from imu_allan.core.noise.params import load_params
from imu_allan.core.noise.simulate import simulate_imu
from imu_allan.core.noise.terms import TERMS
from imu_allan.io.plot import adev_figure, adev_rgb, effect_group
from imu_allan.pipeline.analysis import analyze
from imu_allan.pipeline.hygiene import SessionConfig
from imu_allan.pipeline.session import Session


@pytest.fixture(scope='module')
def result():
    """Analyse a 20 min simulated u-blox record through the pipeline (seeded)."""
    spec = load_params(REPO / 'config' / 'ublox_c102_f9r.yaml')
    t_s, y = simulate_imu(spec, 100.0, 1200.0, seed=7)
    session = Session(SessionConfig())
    session.add(1_700_000_000 * 10 ** 9 + np.round(t_s * 1e9).astype(np.int64), y)
    return analyze(session)


def test_every_term_has_a_group():
    groups = {name: effect_group(name) for name in TERMS}
    assert set(groups.values()) <= {'white', 'bias', 'drift', 'periodic'}
    assert groups['white'] == 'white' and groups['random_walk'] == 'drift'
    assert groups['sinusoid'] == 'periodic' and groups['bias_instability'] == 'bias'


def test_one_dotted_line_per_group_and_the_estimates_marked(result):
    fig = adev_figure(result.curve, result.fits, 'test', figsize=(13, 5.2))
    for ax, axes in zip(fig.axes, (('gyro_x', 'gyro_y', 'gyro_z'),
                                   ('accel_x', 'accel_y', 'accel_z'))):
        dotted = [ln for ln in ax.get_lines() if ln.get_linestyle() == ':']
        groups = [{effect_group(lb.rstrip('_0123456789')) for lb, _, _ in
                   result.fits[a].components} for a in axes if result.fits.get(a)]
        assert len(dotted) == sum(len(g) for g in groups)
        marks = [ln for ln in ax.get_lines() if ln.get_marker() in ('^', 's', 'v')
                 and ln.get_xdata().size]
        estimates = sum(result.fits[a].optimised[s].kind in ('estimate', 'upper_bound')
                        for a in axes for s in ('N', 'K') if result.fits.get(a))
        assert len(marks) >= estimates
    pixels = adev_rgb(result.curve, result.fits, 'test', 520, 208)
    assert pixels.shape == (208, 520, 3) and pixels.dtype == np.uint8
