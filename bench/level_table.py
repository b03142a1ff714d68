"""
The noise level over a record: each axis' level test on real runs (docs/robustness.md).

For every input (``bench/metamorphic.py`` names: adis1 .. adis6, ``adis5:60`` for a first
hour, mpu, sim100 ...) the record is analysed as ``imu-allan analyze`` does and each
axis' Cochran Q test of :func:`imu_allan.core.allan.stretches.level_change` is printed at
the tau the analysis tests (:mod:`imu_allan.pipeline.level_report`): its p-value, the
between-stretch sd of ln N beyond chance, and N's 95 % half-width as reported.

    python bench/level_table.py adis1 adis2 adis3 adis4 adis5 adis6
"""

import argparse

import numpy as np

# This checkout's package first (bench/metamorphic.py puts it on sys.path).
from metamorphic import load  # noqa: I100


def _cell(fit, stretches, axis_index: int) -> str:
    from imu_allan.core.allan.stretches import level_change
    from imu_allan.pipeline.level_report import tested_tau

    n = fit.optimised['N'] if fit is not None else None
    k = None if n is None else tested_tau(fit, stretches, n.value)
    change = None if k is None else level_change(stretches, k, axis_index)
    if change is None:
        return 'not tested'
    half = 100 * ((n.ci95[1] / n.ci95[0]) ** 0.5 - 1)
    return (f'tau {change.tau_s:.3g} s, p {change.p_value:.2g}, excess sd of ln N '
            f'{100 * change.sd_log_avar / 2:.1f} %, N +-{half:.1f} %')


def main() -> None:
    """Print one block per input."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('inputs', nargs='+')
    args = parser.parse_args()
    from imu_allan import AXES
    from imu_allan.pipeline.analysis import analyze
    from imu_allan.pipeline.hygiene import SessionConfig
    from imu_allan.pipeline.session import Session

    for name in args.inputs:
        rec = load(name)
        session = Session(SessionConfig())
        session.add(np.round(rec.t_s * 1e9).astype(np.int64), rec.samples)
        session.flush()
        result = analyze(session, workers=2)
        stretches = session.stretches()
        print(f'{name}: {stretches.rows.size} stretches')
        for j, axis in enumerate(AXES):
            print(f'  {axis}: {_cell(result.fits[axis], stretches, j)}')


if __name__ == '__main__':
    main()
