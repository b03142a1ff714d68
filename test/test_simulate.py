"""
Tests of imu_allan.core.noise.simulate: every generator against its closed-form Allan variance.

Closed forms (IEEE Std 952 annex C, docs/design.md) are written out here so the test does not
depend on imu_allan.core.noise.model.  Statistical checks average the overlapping AVAR of R
independent replicas and accept |mean - theory| < 4.5 standard errors of that mean
(the standard error comes from the replicas' own spread, so it holds for every noise
type), plus 1 % for the point-sampling excess described in the simulate docstring,
which is below 1 % for the cluster sizes used (m >= 16).
"""

import math

import numpy as np
from numpy.testing import assert_allclose
import pytest

from imu_allan import AXES, cli
from imu_allan.core.allan import overlapping_avar
from imu_allan.core.noise.generators import (flicker_noise, gauss_markov_noise, quantization_noise,
                                             random_walk_noise, rate_ramp, sinusoid, white_noise)
from imu_allan.core.noise.simulate import (simulate_axis, simulate_imu, simulate_state_space,
                                           state_space_matrices)
from imu_allan.core.noise.values import AxisNoise, GaussMarkov, NoiseSpec, Sinusoid
from imu_allan.errors import InputError
from imu_allan.io.csv_io import read_csv

RATE_HZ = 50.0
N_SAMPLES = 2 ** 15
N_REPLICAS = 16
M = np.unique(np.geomspace(16, N_SAMPLES // 8, 9).astype(int))
TAU_S = M / RATE_HZ
LN2 = math.log(2.0)


def _replica_avar(generator, seed: int) -> np.ndarray:
    """Overlapping AVAR, shape (N_REPLICAS, len(M)), of independent replicas."""
    rng = np.random.default_rng(seed)
    return np.array([overlapping_avar(generator(rng), M)[0] for _ in range(N_REPLICAS)])


def _assert_matches(avar: np.ndarray, theory: np.ndarray) -> None:
    """Replica-mean AVAR equals theory within 4.5 standard errors + 1 %."""
    mean = avar.mean(axis=0)
    se = avar.std(axis=0, ddof=1) / math.sqrt(avar.shape[0])
    bad = np.abs(mean - theory) > 4.5 * se + 0.01 * theory
    assert not bad.any(), (f'tau {TAU_S[bad]} s: simulated {mean[bad]} vs theory '
                           f'{theory[bad]} (se {se[bad]})')


def _gm_avar(tau_s, q, T):
    """First-order Gauss-Markov AVAR, decaying exponentials (not the paper's exp(+))."""
    x = tau_s / T
    return (q * T) ** 2 / tau_s * (1.0 - (3.0 - 4.0 * np.exp(-x) + np.exp(-2.0 * x)) / (2 * x))


def test_white_noise_avar_is_n2_over_tau():
    N = 2e-3
    avar = _replica_avar(lambda rng: white_noise(N, RATE_HZ, N_SAMPLES, rng), 1)
    _assert_matches(avar, N ** 2 / TAU_S)


def test_gauss_markov_avar_matches_closed_form_and_paper_floor():
    gm = GaussMarkov(B=1e-3, T=3.0)
    avar = _replica_avar(lambda rng: gauss_markov_noise(gm, RATE_HZ, N_SAMPLES, rng), 2)
    _assert_matches(avar, _gm_avar(TAU_S, gm.q, gm.T))
    # Paper eq. 8: the ADEV peak, 0.4365 q sqrt(T) at 1.89 T, equals 0.664 B.
    assert_allclose(math.sqrt(_gm_avar(1.89 * gm.T, gm.q, gm.T)), 0.664 * gm.B, rtol=2e-3)


def test_gauss_markov_is_stationary_with_exact_ar1_coefficient():
    gm = GaussMarkov(B=1e-3, T=0.5)
    x = gauss_markov_noise(gm, RATE_HZ, 4000, np.random.default_rng(3), n_replicas=400)
    var_t = x.var(axis=1)  # across replicas, per time: flat from the first sample on
    rel_se = math.sqrt(2.0 / x.shape[1])
    assert_allclose(var_t[:5], gm.sigma ** 2, rtol=5 * rel_se)
    assert_allclose(var_t[-5:], gm.sigma ** 2, rtol=5 * rel_se)
    phi_hat = np.sum(x[1:] * x[:-1]) / np.sum(x[:-1] ** 2)
    assert_allclose(phi_hat, math.exp(-1.0 / (RATE_HZ * gm.T)), atol=2e-3)


def test_flicker_floor_is_0664_b():
    B = 1e-3
    avar = _replica_avar(lambda rng: flicker_noise(B, RATE_HZ, N_SAMPLES, rng), 4)
    _assert_matches(avar, np.full(M.size, 2.0 * LN2 * B ** 2 / math.pi))


def test_random_walk_avar_is_k2_tau_over_3():
    K = 1e-4
    avar = _replica_avar(lambda rng: random_walk_noise(K, RATE_HZ, N_SAMPLES, rng), 5)
    _assert_matches(avar, K ** 2 * TAU_S / 3.0)


def test_quantization_avar_is_3q2_over_tau2():
    Q = 1e-5
    avar = _replica_avar(lambda rng: quantization_noise(Q, RATE_HZ, N_SAMPLES, rng), 6)
    _assert_matches(avar, 3.0 * Q ** 2 / TAU_S ** 2)


def test_rate_ramp_avar_is_exact():
    R = 1e-6
    t_s = np.arange(N_SAMPLES) / RATE_HZ
    avar, _ = overlapping_avar(rate_ramp(R, t_s), M)
    assert_allclose(avar, R ** 2 * TAU_S ** 2 / 2.0, rtol=1e-6)


def test_sinusoid_avar_matches_phase_average():
    A, f0_hz = 1e-3, 0.37
    t_s = np.arange(N_SAMPLES) / RATE_HZ  # 655 s: 240 periods, so every phase is covered
    y = sinusoid(A, f0_hz, t_s, np.random.default_rng(7))
    m = np.array([1, 5, 20, 50, 100])
    tau = m / RATE_HZ
    avar, _ = overlapping_avar(y, m)
    x = math.pi * f0_hz * tau
    assert_allclose(avar, A ** 2 * (np.sin(x) ** 2 / x) ** 2, rtol=0.02)
    assert_allclose(y.std(), A / math.sqrt(2.0), rtol=0.01)


def test_simulate_axis_sums_terms_with_fixed_draw_order():
    n = 1000
    rng = np.random.default_rng(8)
    noise = AxisNoise(N=1e-3, K=1e-5, R=2e-6, bias=9.80665)
    y = simulate_axis(noise, RATE_HZ, n, rng)
    rng = np.random.default_rng(8)
    t_s = np.arange(n) / RATE_HZ
    expected = (9.80665 + white_noise(1e-3, RATE_HZ, n, rng)
                + random_walk_noise(1e-5, RATE_HZ, n, rng) + 2e-6 * t_s)
    assert_allclose(y, expected, rtol=0, atol=1e-12)
    const = simulate_axis(AxisNoise(bias=-0.25), RATE_HZ, n, rng)
    assert np.all(const == -0.25)


def test_simulate_axis_all_terms_matches_summed_theory():
    gm2 = GaussMarkov(B=5e-4, T=20.0)
    noise = AxisNoise(N=1e-3, B=4e-4, T_B=2.0, K=2e-5, gauss_markov=(gm2,))
    avar = _replica_avar(lambda rng: simulate_axis(noise, RATE_HZ, N_SAMPLES, rng), 9)
    g1 = GaussMarkov(noise.B, noise.T_B)
    theory = (noise.N ** 2 / TAU_S + _gm_avar(TAU_S, g1.q, g1.T)
              + _gm_avar(TAU_S, gm2.q, gm2.T) + noise.K ** 2 * TAU_S / 3.0)
    _assert_matches(avar, theory)


def test_state_space_matrices_hand_computed():
    # dt = 0.01 s, T_B = 100 s, B = 1e-4, K = 2e-6, N = 1e-3 (rad/s units).
    # S_B = 2 B^2 ln2 / (pi 0.4365^2 T_B) = 1.3863e-8 / 59.858 = 2.31598e-10 (paper eq. 8)
    # Qd_GM = S_B T_B / 2 (1 - exp(-2e-4)) = 1.15799e-8 * 1.99980e-4 = 2.31575e-12
    # Qd_RW = K^2 dt = 4e-14;  R = N^2 / dt = 1e-4;  Phi_GM = exp(-1e-4) = 0.999900005
    noise = AxisNoise(N=1e-3, B=1e-4, T_B=100.0, K=2e-6)
    Phi, Qd, H, R = state_space_matrices(noise, 0.01)
    assert_allclose(Phi, [[0.99990000499983, 0.0], [0.0, 1.0]], rtol=1e-12)
    assert_allclose(Qd, [[2.315750e-12, 0.0], [0.0, 4e-14]], rtol=2e-5)
    assert_allclose(H, [[1.0, 1.0]])
    assert_allclose(R, [[1e-4]], rtol=1e-12)
    # A growing exp(+dt/T_B) (the paper's eq. 26/27 typo) would make the model unstable.
    assert Phi[0, 0] < 1.0


def test_state_space_extra_gauss_markov_and_no_gauss_markov():
    dt = 0.02
    Phi, Qd, H, _ = state_space_matrices(
        AxisNoise(N=1e-3, B=1e-4, T_B=50.0, gauss_markov=(GaussMarkov(2e-4, 5.0),)), dt)
    assert Phi.shape == (3, 3) and H.shape == (1, 3)
    assert_allclose(np.diag(Phi), [math.exp(-dt / 50.0), math.exp(-dt / 5.0), 1.0])
    Phi, Qd, _, _ = state_space_matrices(AxisNoise(N=1e-3, K=1e-5), dt)
    assert_allclose(np.diag(Phi), [1.0, 1.0])
    assert_allclose(np.diag(Qd), [0.0, 1e-10 * dt])
    with pytest.raises(InputError, match='T_B'):
        state_space_matrices(AxisNoise(N=1e-3, B=1e-4), dt)


def test_state_space_statistics_match_direct_simulation():
    noise = AxisNoise(N=1e-3, B=1e-3, T_B=0.4, K=1e-4)
    n, r = 3000, 200
    run = simulate_state_space(noise, RATE_HZ, n, np.random.default_rng(10), n_replicas=r)
    assert run.y.shape == (n, r) and run.x.shape == (n, r, 2)
    Phi, Qd, H, R = state_space_matrices(noise, 1.0 / RATE_HZ)
    gm = GaussMarkov(noise.B, noise.T_B)
    direct = gauss_markov_noise(gm, RATE_HZ, n, np.random.default_rng(11), n_replicas=r)
    b_gm = run.x[:, :, 0]
    for series in (b_gm, direct):  # same stationary variance and AR(1) coefficient
        assert_allclose(series.var(), gm.sigma ** 2, rtol=0.05)
        phi_hat = np.sum(series[1:] * series[:-1]) / np.sum(series[:-1] ** 2)
        assert_allclose(phi_hat, Phi[0, 0], atol=3e-3)
    rw_steps = np.diff(run.x[:, :, 1], axis=0)
    assert_allclose(rw_steps.var(), Qd[1, 1], rtol=0.02)
    assert np.all(run.x[0, :, 1] == 0.0)
    v = run.y - run.x @ H[0]
    assert_allclose(v.var(), R[0, 0], rtol=0.02)


def test_simulate_imu_shape_seed_and_axis_independence():
    gyro = AxisNoise(N=1e-4, B=5e-5, T_B=30.0, K=1e-6)
    accel = AxisNoise(N=6e-4, B=3e-4, K=1e-5)  # flicker B
    axes = {a: (gyro if a.startswith('gyro') else accel) for a in AXES}
    axes['accel_z'] = AxisNoise(N=6e-4, bias=9.80665)
    spec = NoiseSpec('test', axes)
    t_s, y = simulate_imu(spec, 100.0, 60.0, seed=12)
    assert t_s.shape == (6000,) and y.shape == (6000, 6)
    assert_allclose(t_s[:3], [0.0, 0.01, 0.02])
    assert_allclose(y[:, 5].mean(), 9.80665, atol=5 * 6e-4 * 10 / math.sqrt(6000))
    t2, y2 = simulate_imu(spec, 100.0, 60.0, seed=12)
    assert np.array_equal(y, y2) and np.array_equal(t_s, t2)
    _, y3 = simulate_imu(spec, 100.0, 60.0, seed=13)
    assert not np.any(y3[:, :5] == y[:, :5])
    changed = NoiseSpec('test', {**axes, 'gyro_y': AxisNoise(N=1.0)})
    _, y4 = simulate_imu(changed, 100.0, 60.0, seed=12)
    keep = [0, 2, 3, 4, 5]
    assert np.array_equal(y4[:, keep], y[:, keep])
    assert not np.array_equal(y4[:, 1], y[:, 1])


@pytest.mark.parametrize('kwargs, text', [
    ({'rate_hz': 0.0, 'n_samples': 10}, 'sample rate'),
    ({'rate_hz': float('nan'), 'n_samples': 10}, 'sample rate'),
    ({'rate_hz': 100.0, 'n_samples': -1}, 'number of samples'),
])
def test_simulate_axis_rejects_bad_grid(kwargs, text):
    with pytest.raises(InputError, match=text):
        simulate_axis(AxisNoise(N=1.0), rng=np.random.default_rng(0), **kwargs)


def test_sinusoid_in_axis_noise_is_simulated():
    noise = AxisNoise(sinusoids=(Sinusoid(A=2.0, f0_hz=1.0),))
    y = simulate_axis(noise, RATE_HZ, 500, np.random.default_rng(14))
    assert_allclose(np.abs(y).max(), 2.0, rtol=1e-3)
    assert_allclose(y[::50], y[0], atol=1e-9)  # period 1 s = 50 samples


def main(argv) -> int:
    """
    Run ``imu-allan`` with only the simulate sub-command registered.

    The real dispatcher and its error handling run; the other sub-commands (written
    separately) are left out so this file tests simulate alone.

    """
    saved = cli.SUBCOMMANDS
    cli.SUBCOMMANDS = ('simulate',)
    try:
        return cli.main(argv)
    finally:
        cli.SUBCOMMANDS = saved


PARAMS_YAML = """\
name: cli test
axes:
  gyro: {N: 0.007 deg/s/sqrt(Hz), B: 10 deg/h, T_B: 30 s}
  accel: {N: 60 ug/sqrt(Hz)}
  accel_z: {bias: 9.80665}
"""


def test_cli_simulate_writes_csv_that_reads_back(tmp_path, capsys):
    params = tmp_path / 'p.yaml'
    params.write_text(PARAMS_YAML)
    out = tmp_path / 'sim.csv.gz'
    code = main(['simulate', '--params', str(params), '--rate', '50', '--duration', '20',
                 '--out', str(out), '--seed', '5'])
    assert code == 0
    err = capsys.readouterr().err
    assert '1000 samples' in err and 'seed 5' in err and err.count('\n') == 1
    data = read_csv(out)
    assert tuple(data.columns) == AXES
    t_s, y = data.t_s, data.samples
    t_ref, y_ref = simulate_imu(_spec_from_text(PARAMS_YAML), 50.0, 20.0, seed=5)
    assert_allclose(t_s, t_ref, atol=1e-9)
    assert_allclose(y, y_ref, rtol=1e-9, atol=1e-12)


def _spec_from_text(text: str) -> NoiseSpec:
    import yaml

    from imu_allan.core.noise.params import parse_params
    return parse_params(yaml.safe_load(text))


@pytest.mark.parametrize('yaml_text, extra, needle', [
    ('axes: {gyro: {K: 10 deg/h}}\n', [], 'axes.gyro.K'),
    ('name: x\n', [], 'missing key axes'),
    (PARAMS_YAML, ['--rate', '-5'], '--rate'),
    (PARAMS_YAML, ['--out-ext'], None),
])
def test_cli_simulate_bad_input_exits_2_with_one_line(tmp_path, capsys, yaml_text, extra,
                                                      needle):
    params = tmp_path / 'p.yaml'
    params.write_text(yaml_text)
    if extra == ['--out-ext']:
        out, extra = tmp_path / 'x.txt', []
        needle = 'output format'
    else:
        out = tmp_path / 'x.csv'
    args = ['simulate', '--params', str(params), '--rate', '50', '--duration', '1',
            '--out', str(out)]
    code = main(args + extra)
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith('imu-allan: error: ') and err.count('\n') == 1 and needle in err
    assert not out.exists()


def test_cli_simulate_writes_bag_that_reads_back(tmp_path, capsys):
    rosbags_highlevel = pytest.importorskip('rosbags.highlevel')
    from rosbags.typesys import get_typestore, Stores

    params = tmp_path / 'p.yaml'
    params.write_text(PARAMS_YAML)
    out = tmp_path / 'simbag'  # no suffix: a rosbag2 directory
    assert main(['simulate', '--params', str(params), '--rate', '20', '--duration', '5',
                 '--out', str(out), '--seed', '1', '--start', '1000']) == 0
    assert '100 samples' in capsys.readouterr().err
    store = get_typestore(Stores.ROS2_JAZZY)
    with rosbags_highlevel.AnyReader([out], default_typestore=store) as reader:
        msgs = [reader.deserialize(raw, con.msgtype) for con, _, raw in reader.messages()]
    _, y_ref = simulate_imu(_spec_from_text(PARAMS_YAML), 20.0, 5.0, seed=1)
    stamps = [m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in msgs]
    assert_allclose(stamps, 1000.0 + np.arange(100) / 20.0, rtol=0, atol=1e-9)
    gyro = [[m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z] for m in msgs]
    accel = [[m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z]
             for m in msgs]
    assert_allclose(np.hstack([gyro, accel]), y_ref, rtol=0, atol=1e-15)
    # Covariance fields carry the white-noise variance N^2 * rate.
    n_gyro = 0.007 * math.pi / 180.0
    assert_allclose(msgs[0].angular_velocity_covariance[0], n_gyro ** 2 * 20.0, rtol=1e-9)
