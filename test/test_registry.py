"""
The term registry is the only dispatch: one entry adds a term everywhere.

A term added by its entry alone is fitted, simulated, searched, exported, planned and
documented.
The toy term is registered for one test only (the ``toy`` fixture): the diff that adds a
real term is its entry in imu_allan/core/noise/terms.py plus tests like these.  The
docs' copy of the registry table is checked against the registry itself.
"""

import json
import math

import numpy as np
from numpy.testing import assert_allclose
import pytest
import yaml

from conftest import REPO
from imu_allan import AXES
from imu_allan.cli import main
from imu_allan.core.allan import allan_curve
from imu_allan.core.fit import fit_axis
from imu_allan.core.noise.generators import white_noise
from imu_allan.core.noise.model import avar_model, avar_terms, term_table
from imu_allan.core.noise.params import dump_params, parse_params, save_params
from imu_allan.core.noise.shapes import _gcov_white, _PSD_PHASE
from imu_allan.core.noise.simulate import simulate_axis, simulate_imu
from imu_allan.core.noise.terms import Key, Term, TERMS
from imu_allan.core.noise.units import quoted, to_si
from imu_allan.core.noise.values import AxisNoise, NoiseSpec, TermValue
from imu_allan.core.outputs.covering import N_MARGIN
from imu_allan.core.outputs.exports import kalibr_yaml
from imu_allan.core.outputs.kalman import kalman_model
from imu_allan.core.search import search_axis

RATE_HZ = 50.0
W, K = 2e-3, 2e-5      # the toy's level [rad/s*s^0.5] and a random walk beside it


def _toy() -> Term:
    """Return a second white-noise term, 'toy' with level W: all it needs is this entry."""
    return Term(
        'toy', ('W',), (), lambda tau: 1.0 / np.asarray(tau, dtype=np.float64), _gcov_white,
        lambda c: {'W': math.sqrt(max(c, 0.0))}, lambda v: v * v, ('u*s^0.5',),
        keys=(Key('W', ('deg/sqrt(h)', 'ug/sqrt(Hz)')),),
        simulate=lambda p, f, n, rng: white_noise(p['W'], f, n, rng),
        title='toy white noise', kalman='white', effect=True,
        psd_phase=_PSD_PHASE['white'])


@pytest.fixture
def toy(monkeypatch):
    """Register the toy term for one test."""
    monkeypatch.setitem(TERMS, 'toy', _toy())
    return AxisNoise(K=K, extra=(TermValue('toy', (W,)),))


def test_the_docs_show_the_registry():
    text = (REPO / 'docs' / 'architecture.md').read_text()
    start = text.index('<!-- term-table')
    table = text[text.index('\n', start) + 1:text.index('<!-- end term-table -->')]
    assert table.strip() == term_table().strip()


def test_a_toy_term_is_modelled_simulated_and_fitted(toy):
    tau = np.array([0.1, 1.0, 10.0])
    assert set(avar_terms(tau, toy)) == {'toy', 'random_walk'}
    assert_allclose(avar_model(tau, toy), W ** 2 / tau + K ** 2 * tau / 3.0, rtol=1e-14)
    y = simulate_axis(toy, RATE_HZ, 200_000, np.random.default_rng(3))
    curve = allan_curve(y, RATE_HZ, 'octave')
    # The simulated curve follows the model at the short taus, where it is sharp.
    short = curve.tau_s < 2.0
    assert_allclose(curve.avar[short, 0], avar_model(curve.tau_s[short], toy), rtol=0.05)
    fit = fit_axis(curve.tau_s, curve.avar[:, 0], curve.edf[:, 0], RATE_HZ, y.size,
                   terms=('toy', 'random_walk'), unit='rad/s')
    p = fit.optimised['toy.W']
    assert p.kind == 'estimate' and p.ci95[0] <= W <= p.ci95[1], p
    assert_allclose(p.value, W, rtol=0.03)
    assert fit.model.extra[0].term == 'toy'
    assert_allclose(fit.model.extra[0].values[0], p.value, rtol=1e-12)
    assert fit.to_json()['params']['toy.W']['unit'] == 'rad/s*s^0.5'


def test_the_search_adds_a_toy_effect(toy):
    y = simulate_axis(toy, RATE_HZ, 200_000, np.random.default_rng(4))
    curve = allan_curve(y, RATE_HZ, 'octave')
    got = search_axis(curve.tau_s, curve.avar[:, 0], curve.edf[:, 0], RATE_HZ, y.size,
                      unit='rad/s', base_labels=('random_walk',), effects=('toy',))
    assert [s.effect for s in got.steps] == ['toy']
    assert_allclose(got.fit.optimised['toy.W'].value, W, rtol=0.05)


def test_a_toy_term_is_exported(toy):
    spec = NoiseSpec(name='toy imu', axes={a: toy for a in AXES})
    # Parameter files: its list entry round-trips, in SI and in quoted units.
    dumped = dump_params(spec)
    assert dumped['axes']['gyro'] == {'K': K, 'toy': [{'W': W}]}
    assert parse_params(dumped) == spec
    assert parse_params(dump_params(spec, with_units=True)).axes['accel_x'].extra[0].values[0] \
        == pytest.approx(W, rel=1e-5)
    assert quoted('W', 'gyro', W)[1] == 'deg/sqrt(h)'
    assert to_si('1 deg/sqrt(h)', 'W', 'gyro') == pytest.approx(math.radians(1.0) / 60.0)
    # Its Kalman role 'white': R and the Kalibr noise density take it.
    km = kalman_model(spec.axes, RATE_HZ)
    assert_allclose(np.diag(km.Rd), W ** 2 * RATE_HZ, rtol=1e-12)
    assert_allclose(np.diag(km.Qc)[1::2], K ** 2, rtol=1e-12)
    # Kalibr's covering pair covers it too (a white + random-walk model is its own cover,
    # N with the run-to-run margin).
    kalibr = yaml.safe_load(kalibr_yaml(spec.axes, RATE_HZ))
    assert_allclose(kalibr['gyroscope_noise_density'], N_MARGIN * W, rtol=1e-5)
    assert_allclose(kalibr['accelerometer_random_walk'], K, rtol=1e-5)
    # ... and the six-axis simulator draws it.
    _, samples = simulate_imu(spec, RATE_HZ, 200.0, seed=1)
    assert_allclose(samples[:, 0].std(), W * math.sqrt(RATE_HZ), rtol=0.05)


def test_a_toy_term_is_documented(toy):
    row = next(line for line in term_table().splitlines() if line.startswith('| `toy`'))
    assert row == ('| `toy` | toy white noise | W [u*s^0.5] | list `toy`: W | yes | '
                   'R (adds to S_N) |')


def _plan_json(capsys, path) -> dict:
    assert main(['plan', '--params', str(path), '--rate', str(RATE_HZ),
                 '--format', 'json']) == 0
    return json.loads(capsys.readouterr().out)['axes']['gyro_x']['params']


def test_a_toy_term_is_planned(toy, tmp_path, capsys):
    # `imu-allan plan --params` plans every registry term the file holds: the toy's W
    # gets its own row, and its white noise beside K delays K's plan.
    save_params(NoiseSpec(name='toy imu', axes={'gyro_x': toy}), tmp_path / 'toy.yaml')
    save_params(NoiseSpec(name='K alone', axes={'gyro_x': AxisNoise(K=K)}),
                tmp_path / 'k.yaml')
    params = _plan_json(capsys, tmp_path / 'toy.yaml')
    alone = _plan_json(capsys, tmp_path / 'k.yaml')
    assert sorted(params) == ['K', 'toy.W']
    assert_allclose(params['toy.W']['value'], W, rtol=1e-12)
    assert params['toy.W']['kind'] == 'predicted' and math.isfinite(params['toy.W']['time_s'])
    assert params['K']['time_s'] > alone['K']['time_s']
