"""
What a diagnosis reports: findings per step, per axis and for the whole record.

Part of :mod:`imu_allan.core.diagnose`.
"""

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from imu_allan.core.diagnose.gap import GAP_OK
from imu_allan.core.fit.result import AxisFit, json_floats, json_num
from imu_allan.core.noise.terms import TERMS


class Finding(NamedTuple):
    """
    One missing effect that the diagnosis named and added.

    Attributes
    ----------
    effect : str
        One of :data:`EFFECTS` (a term name).
    params : dict of str to float
        The effect's parameters in SI (docs/contracts.md symbols), e.g. {'A': .., 'f0_hz': ..}.
    ci95 : dict of str to tuple
        95 % interval of each parameter (the fit's profile interval; for a frequency
        checked against the periodogram, the peak +- one frequency bin).
    units : dict of str to str
        Unit of each parameter.
    tau_range_s : tuple of float
        Averaging times where the effect changes ln ADEV by more than s(tau) [s].
    shape : str
        Shape of the disagreement the effect explains (see :class:`Band`).
    gap_before : float
        Gap before the step [-].
    gap_after : float
        Gap after the step [-].
    delta_chi2 : float
        Drop of the GLS chi-square bought by the effect [-].
    note : str
        E.g. the periodogram check of a sinusoid.

    """

    effect: str
    params: dict
    ci95: dict
    units: dict
    tau_range_s: tuple
    shape: str
    gap_before: float
    gap_after: float
    delta_chi2: float
    note: str = ''

    def to_json(self) -> dict:
        """Return the docs/contracts.md entry {effect, params, tau_range_s} plus details."""
        return {'effect': self.effect, 'params': {k: json_num(v) for k, v in self.params.items()},
                'ci95': {k: [json_num(v[0]), json_num(v[1])] for k, v in self.ci95.items()},
                'units': dict(self.units),
                'tau_range_s': [float(v) for v in self.tau_range_s], 'shape': self.shape,
                'gap_before': json_num(self.gap_before), 'gap_after': json_num(self.gap_after),
                'delta_chi2': json_num(self.delta_chi2), 'note': self.note}


@dataclass(frozen=True)
class AxisDiagnosis:
    """
    Diagnosis of one axis.

    Attributes
    ----------
    axis : str
        Axis name.
    unit : str
        Unit of the samples.
    base_terms : tuple of str
        Fit terms of the base model.
    terms : tuple of str
        Fit terms of the final model.
    missing : tuple of Finding
        Effects added, in order.
    gap_before, gap_after : float
        Gap of the base model and of the final model [-].
    gaps : tuple of float
        Gap after each step, starting with the base model's.
    tau_s : np.ndarray
        Shape (k,), averaging times of the comparison [s].
    adev : np.ndarray
        Shape (k,), measured Allan deviation [unit].
    s_ln : np.ndarray
        Shape (k,), standard error of ln ADEV, s(tau) [-].
    adev_before, adev_after : np.ndarray
        Shape (k,), simulated (replica-mean) ADEV of the base and the final model.
    bands_before, bands_after : tuple of Band
        Disagreement bands of the base and the final model.
    chi2_before, chi2_after : float
        GLS chi-square of the base and the final fit; ``dof`` the final fit's dof.
    dof : int
        Degrees of freedom of the final fit.
    fit_before, fit_after : AxisFit
        The base and the final fit.
    summary : str
        One line, e.g. 'gyro_z: missing sinusoid at 0.011 Hz (period 90 s, amplitude
        2.1e-4 rad/s); gap 7.9 -> 1.1'.
    notes : tuple of str
        Further remarks (rejected candidates, an unexplained disagreement).

    """

    axis: str
    unit: str
    base_terms: tuple
    terms: tuple
    missing: tuple
    gap_before: float
    gap_after: float
    gaps: tuple
    tau_s: np.ndarray
    adev: np.ndarray
    s_ln: np.ndarray
    adev_before: np.ndarray
    adev_after: np.ndarray
    bands_before: tuple
    bands_after: tuple
    chi2_before: float
    chi2_after: float
    dof: int
    fit_before: AxisFit | None = field(repr=False, default=None)
    fit_after: AxisFit | None = field(repr=False, default=None)
    summary: str = ''
    notes: tuple = ()

    @property
    def consistent(self) -> bool:
        """Whether the final model is consistent: its gap is at most GAP_OK."""
        return self.gap_after <= GAP_OK

    def to_json(self) -> dict:
        """Return the axis entry of docs/contracts.md (missing, gap_before, gap_after) and more."""
        return {'missing': [f.to_json() for f in self.missing],
                'gap_before': json_num(self.gap_before), 'gap_after': json_num(self.gap_after),
                'gaps': [json_num(g) for g in self.gaps], 'consistent': bool(self.consistent),
                'base_terms': list(self.base_terms), 'terms': list(self.terms),
                'chi2_before': json_num(self.chi2_before), 'chi2_after': json_num(self.chi2_after),
                'dof': int(self.dof),
                'bands_before': [b.to_json() for b in self.bands_before],
                'bands_after': [b.to_json() for b in self.bands_after],
                'tau_s': json_floats(self.tau_s), 'adev': json_floats(self.adev),
                's_ln': json_floats(self.s_ln), 'adev_sim_before': json_floats(self.adev_before),
                'adev_sim_after': json_floats(self.adev_after),
                'params_after': self.fit_after.to_json()['params'] if self.fit_after else {},
                'summary': self.summary, 'notes': list(self.notes)}


@dataclass(frozen=True)
class DiagnoseResult:
    """
    Diagnosis of every axis of a record.

    Attributes
    ----------
    axes : dict of str to AxisDiagnosis or None
        Per axis; None where the axis cannot be fitted (frozen, too short).
    rate_hz : float
        Sample rate [Hz].
    n_samples : int
        Samples behind the curve.
    duration_s : float
        Duration [s].
    base_model : tuple of str
        Base-model effect names.
    n_replicas : int
        Simulated replicas per model.
    raw_checked : bool
        True when raw samples were available for the periodogram check.
    source : str
        What was diagnosed.
    warnings : tuple of str
        Input warnings.

    """

    axes: dict
    rate_hz: float
    n_samples: int
    duration_s: float
    base_model: tuple
    n_replicas: int
    raw_checked: bool
    source: str = ''
    warnings: tuple = ()

    def summary_lines(self) -> list:
        """Return one line per axis (see :class:`AxisDiagnosis`)."""
        return [d.summary if d is not None else f'{a}: not diagnosed (no usable curve)'
                for a, d in self.axes.items()]

    def table_markdown(self) -> str:
        """Return the gap table (the paper's table 3: RMS error before and after)."""
        rows = ['| axis | base model gap | final gap | missing effects | gap per step |',
                '| --- | --- | --- | --- | --- |']
        for a, d in self.axes.items():
            if d is None:
                rows.append(f'| {a} | - | - | (not diagnosed) | - |')
                continue
            names = ', '.join(f.effect for f in d.missing) or 'none'
            steps = ' -> '.join(f'{g:.2f}' for g in d.gaps)
            rows.append(f'| {a} | {d.gap_before:.2f} | {d.gap_after:.2f} | {names} | '
                        f'{steps} |')
        return '\n'.join(rows) + '\n'

    def to_json(self) -> dict:
        """Return the diagnose JSON of docs/contracts.md."""
        return {'source': self.source, 'sample_rate_hz': float(self.rate_hz),
                'n_samples': int(self.n_samples), 'duration_s': float(self.duration_s),
                'base_model': list(self.base_model), 'n_replicas': int(self.n_replicas),
                'raw_checked': bool(self.raw_checked),
                'gap_definition': 'RMS over tau of (ln ADEV_meas - ln ADEV_sim) / s(tau), '
                                  's = sqrt(trigamma(edf / 2)) / 2',
                'axes': {a: (d.to_json() if d is not None else None)
                         for a, d in self.axes.items()},
                'summary': self.summary_lines(), 'warnings': list(self.warnings)}


def _finding_text(f: Finding) -> str:
    return TERMS[f.effect].summary(f.params, f.units)


def summary_line(d: AxisDiagnosis) -> str:
    """
    Return the axis' line, e.g. 'gyro_z: missing sinusoid at 0.011 Hz (...); gap 7.9 -> 1.1'.

    Parameters
    ----------
    d : AxisDiagnosis
        The diagnosis.

    Returns
    -------
    str
        The line.

    """
    gaps = f'gap {d.gap_before:.2g} -> {d.gap_after:.2g}'
    if d.missing:
        what = ' + '.join(_finding_text(f) for f in d.missing)
        tail = '' if d.consistent else ' (still inconsistent)'
        return f'{d.axis}: missing {what}; {gaps}{tail}'
    if d.consistent:
        return f'{d.axis}: nothing missing, the base model is consistent; gap {d.gap_before:.2g}'
    bands = ', '.join(f'{b.shape} {b.sign} at {b.tau_range_s[0]:.3g}-{b.tau_range_s[1]:.3g} s'
                      for b in d.bands_before)
    return (f'{d.axis}: base model inconsistent (gap {d.gap_before:.2g}'
            + (f'; {bands}' if bands else '') + ') but no listed effect is supported')
