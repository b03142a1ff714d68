"""
Reproduce Maia, Silva, De Lima and Meneses on simulated sensors: read-off against fit.

Usage: ``.venv/bin/python bench/reproduce_paper.py [--hours 10] [--seed 1] [--out DIR]``
(run by ``make bench``).  For each of the paper's IMUs (Xsens MTi-7 at 100 Hz, u-blox
C102-F9R at 50 Hz) a record of ``--hours`` (the paper recommends at least 10 h) is
simulated from the paper's table 2 values (``config/*.yaml``) with our state-space
simulator, and the X axes are identified two ways:

* the paper's way: the read-off of its section 2.2 (IEEE Std 952 lines: N at tau = 1 s,
  K at tau = 3 s, B = ADEV minimum / 0.664, T_B = tau of the minimum / 1.89), which is
  ``AxisFit.nominal``;
* ours: the effect search and GLS fit every analysis runs, with 95 % intervals.

Printed as markdown: both beside the truth (table 2) and the paper's table 1, whether
the truth lies inside our interval, and table 3's RMS error of the model ADEV curves
against the simulated ("measured") curve for the read-off and the optimised values, with
their ratio beside the paper's 3.5-4.9.  Figures like the paper's 2-5 and 8-9 (measured
curve, read-off model, optimised model, truth, and for the MTi-7 the datasheet lines of
table 4) go to ``--out`` (default bench/out/paper/).
"""

import argparse
from pathlib import Path
import time

import numpy as np

from imu_allan import AXIS_UNITS
from imu_allan.core.allan import allan_curve
from imu_allan.core.noise.model import adev_model
from imu_allan.core.noise.params import load_params
from imu_allan.core.noise.shapes import FLICKER_AVAR
from imu_allan.core.noise.simulate import simulate_imu
from imu_allan.core.noise.values import AxisNoise
from imu_allan.core.search import search_axis

REPO = Path(__file__).resolve().parents[1]
#: IMU -> (table 2 config, table 1 config, rate [Hz], paper's table 3 RMS (read-off,
#: optimised) per sensor, datasheet (N, B) per sensor from table 4 or None).
IMUS = {
    'MTi-7': ('xsens_mti7.yaml', 'xsens_mti7_readoff.yaml', 100.0,
              {'accel': (3.9e-4, 1.0e-4), 'gyro': (4.2e-5, 8.6e-6)},
              {'accel': (12.0e-4, 3.0e-4), 'gyro': (12.0e-5, 4.8e-5)}),
    'C102-F9R': ('ublox_c102_f9r.yaml', 'ublox_c102_f9r_readoff.yaml', 50.0,
                 {'accel': (4.2e-4, 1.2e-4), 'gyro': (1.8e-3, 5.0e-4)}, None),
}
AXIS_OF = {'gyro': 'gyro_x', 'accel': 'accel_x'}
SYMBOLS = ('N', 'B', 'K', 'T_B')


def _noise(params: dict) -> AxisNoise:
    """Return the AxisNoise of read-off or fitted parameters (NaN or missing: absent)."""
    def v(sym):
        p = params.get(sym)
        x = float(p.value) if p is not None else float('nan')
        return x if np.isfinite(x) and x > 0 else 0.0
    t_b = v('T_B')
    return AxisNoise(N=v('N'), B=v('B') if t_b else 0.0, T_B=t_b or None, K=v('K'))


def _rms(model: np.ndarray, measured: np.ndarray) -> float:
    """Table 3's figure: RMS of the ADEV difference over the measured taus [unit]."""
    ok = np.isfinite(measured) & np.isfinite(model)
    return float(np.sqrt(np.mean((model[ok] - measured[ok]) ** 2)))


def _rms_log(model: np.ndarray, measured: np.ndarray) -> float:
    """RMS of ln(model / measured): every tau counts alike, whatever its ADEV."""
    ok = np.isfinite(measured) & np.isfinite(model) & (model > 0) & (measured > 0)
    return float(np.sqrt(np.mean(np.log(model[ok] / measured[ok]) ** 2)))


def _g(x: float) -> str:
    return 'n/a' if not np.isfinite(x) else f'{x:.3g}'


def _figure(path: Path, title: str, curve, j: int, lines: dict, unit: str) -> None:
    from matplotlib.figure import Figure
    from matplotlib.ticker import LogFormatter

    tau = curve.tau_s
    fig = Figure(figsize=(6.4, 4.6))
    ax = fig.subplots()
    ax.fill_between(tau, curve.adev_lo[:, j], curve.adev_hi[:, j], color='0.7', alpha=0.5,
                    lw=0, label='simulated record, 95 % band')
    ax.loglog(tau, curve.adev[:, j], 'k.', ms=4, label='simulated ("measured") ADEV')
    styles = {'read-off (paper sec. 2.2)': ('tab:orange', '--'),
              'optimised (imu_allan)': ('tab:blue', '-'),
              'truth (paper table 2)': ('tab:green', ':'),
              'paper table 1': ('tab:purple', '-.'),
              'datasheet (table 4)': ('tab:red', (0, (1, 3)))}
    for name, adev in lines.items():
        colour, style = styles[name]
        ax.loglog(tau, adev, color=colour, ls=style, lw=1.4, label=name)
    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_formatter(LogFormatter(labelOnlyBase=True))
        axis.set_minor_formatter(LogFormatter(labelOnlyBase=True))
    ax.set_xlabel('averaging time tau [s]')
    ax.set_ylabel(f'ADEV [{unit}]')
    ax.grid(True, which='major', alpha=0.3)
    ax.legend(fontsize=7)
    ax.set_title(title, fontsize=9)
    fig.savefig(path, dpi=110, bbox_inches='tight')


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    ap.add_argument('--hours', type=float, default=10.0)
    ap.add_argument('--seed', type=int, default=1)
    ap.add_argument('--out', type=Path, default=REPO / 'bench' / 'out' / 'paper')
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    params_rows, rms_rows = [], []
    for imu, (cfg2, cfg1, rate, paper_rms, datasheet) in IMUS.items():
        spec2 = load_params(REPO / 'config' / cfg2)
        spec1 = load_params(REPO / 'config' / cfg1)
        t0 = time.process_time()
        _, y = simulate_imu(spec2, rate, args.hours * 3600.0, seed=args.seed)
        cols = [0, 3]                                   # gyro_x, accel_x
        curve = allan_curve(y[:, cols], rate, taus='dense', confidence=0.95)
        for j, sensor in enumerate(('gyro', 'accel')):
            axis = AXIS_OF[sensor]
            unit = AXIS_UNITS[axis]
            s = search_axis(curve.tau_s, curve.avar[:, j], curve.edf[:, j], rate, y.shape[0],
                            raw=y[:, cols[j]], unit=unit)
            fit = s.fit
            truth, table1 = spec2.axes[axis], spec1.axes[axis]
            for sym in SYMBOLS:
                opt = fit.optimised[sym]
                true = getattr(truth, sym)
                lo, hi = opt.ci95
                inside = 'yes' if lo <= true <= hi else 'no'
                params_rows.append(
                    f'| {imu} | {sensor} | {sym} | {_g(true)} | {_g(getattr(table1, sym))} | '
                    f'{_g(fit.nominal[sym].value)} | {_g(opt.value)} | [{_g(lo)}, {_g(hi)}] | '
                    f'{opt.kind} | {inside} |')
            tau, adev = curve.tau_s, curve.adev[:, j]
            lines = {'read-off (paper sec. 2.2)': adev_model(tau, _noise(fit.nominal)),
                     'optimised (imu_allan)': np.sqrt(fit.avar_at(tau)),
                     'truth (paper table 2)': adev_model(tau, truth),
                     'paper table 1': adev_model(tau, table1)}
            if datasheet:
                n_ds, b_ds = datasheet[sensor]
                lines['datasheet (table 4)'] = np.sqrt(n_ds ** 2 / tau + FLICKER_AVAR * b_ds ** 2)
            rms = {k: _rms(v, adev) for k, v in lines.items()}
            rel = {k: _rms_log(v, adev) for k, v in lines.items()}
            ratio = rms['read-off (paper sec. 2.2)'] / rms['optimised (imu_allan)']
            paper = paper_rms[sensor]
            rms_rows.append(
                f'| {imu} | {sensor} ({unit}) | {_g(rms["read-off (paper sec. 2.2)"])} | '
                f'{_g(rms["optimised (imu_allan)"])} | {ratio:.1f} | '
                f'{_g(rms["truth (paper table 2)"])} | {_g(paper[0])} | {_g(paper[1])} | '
                f'{paper[0] / paper[1]:.1f} | {rel["read-off (paper sec. 2.2)"]:.3f} | '
                f'{rel["optimised (imu_allan)"]:.3f} | {rel["truth (paper table 2)"]:.3f} | '
                f'{", ".join(fit.terms)} |')
            name = f'{imu.lower().replace("-", "")}_{sensor}.png'
            _figure(args.out / name, f'{imu} {sensor} X, {args.hours:g} h at {rate:g} Hz '
                    f'(seed {args.seed})', curve, j, lines, unit)
        print(f'{imu}: {y.shape[0]:,} samples simulated and analysed in '
              f'{time.process_time() - t0:.1f} CPU s', flush=True)
    print(f'\nIdentified parameters ({args.hours:g} h per IMU, seed {args.seed}; SI units)\n')
    print('| IMU | sensor | param | truth (table 2) | paper table 1 | read-off | optimised | '
          '95 % interval | kind | truth inside |')
    print('|---|---|---|---|---|---|---|---|---|---|')
    print('\n'.join(params_rows))
    print('\nRMS error of the model ADEV against the simulated curve (table 3)\n')
    print('| IMU | sensor | read-off | optimised | ratio | truth | paper read-off | '
          'paper optimised | paper ratio | ln-RMS read-off | ln-RMS optimised | '
          'ln-RMS truth | terms found |')
    print('|---|---|---|---|---|---|---|---|---|---|---|---|---|')
    print('\n'.join(rms_rows))
    print(f'\nfigures in {args.out}')


if __name__ == '__main__':
    main()
