"""
ADEV figures drawn with matplotlib (Agg and SVG canvases, no pyplot).

Measured curves with confidence bands, the fitted model and each term's
contribution, gyro and accelerometer in two panels with units.
"""

from pathlib import Path
import textwrap

from matplotlib import colormaps
from matplotlib.figure import Figure
from matplotlib.ticker import LogFormatter, NullLocator
import numpy as np

from imu_allan import ACCEL_AXES, AXES, GYRO_AXES
from imu_allan.core.noise.terms import base_name, TERMS
from imu_allan.core.noise.words import spoken
from imu_allan.io import FIGURE_FORMATS

_COLOURS = {'x': 'tab:red', 'y': 'tab:green', 'z': 'tab:blue'}
_PANELS = ((GYRO_AXES, 'gyro ADEV [rad/s]'), (ACCEL_AXES, 'accel ADEV [m/s\u00b2]'))


def subplots(nrows: int, ncols: int, **kwargs):
    """
    Return a Figure and its axes without pyplot (its import and a GUI backend).

    A bare Figure saves with Agg (PNG) or SVG; with :func:`_plain_log_labels` before
    saving, a plot costs a fraction of a second instead of about two.
    """
    fig = Figure(figsize=kwargs.pop('figsize'))
    return fig, fig.subplots(nrows, ncols, **kwargs)


def _plain_log_labels(fig) -> None:
    """
    Label log axes 1e-05 instead of 10^-5: the default needs the mathtext parser.

    No minor ticks: every tick is an object that each saved format lays out anew, a
    large share of a figure's time; the decades carry labels and a grid.
    """
    for ax in fig.axes:
        for axis, scale in ((ax.xaxis, ax.get_xscale()), (ax.yaxis, ax.get_yscale())):
            if scale == 'log':
                axis.set_major_formatter(LogFormatter(labelOnlyBase=True))
                axis.set_minor_locator(NullLocator())


def warm_fonts() -> None:
    """
    Load the font the figures use (a quarter of a second on the first text drawn).

    Called where the fork server of the workers starts, so that every worker forked
    from it draws at once (see :mod:`imu_allan.io.plot_preload`).
    """
    from matplotlib.font_manager import FontProperties, findfont, get_font

    get_font(findfont(FontProperties()))


def save_figure(fig, base: Path, tight: bool = True, formats: tuple = FIGURE_FORMATS) -> list:
    """Write base.png and/or base.svg; ``tight`` crops to the artists (one more draw each)."""
    _plain_log_labels(fig)
    paths = []
    for ext in formats:
        path = base.with_suffix(f'.{ext}')
        fig.savefig(path, dpi=130 if ext == 'png' else None,
                    bbox_inches='tight' if tight else None)
        paths.append(path)
    return paths


def plot_result(result, base, formats: tuple = FIGURE_FORMATS) -> list:
    """
    Draw the measured ADEV of the six axes with the fitted model and its terms.

    Parameters
    ----------
    result : imu_allan.pipeline.analysis.AnalysisResult
        The analysis to draw.
    base : str or Path
        Output path without suffix.
    formats : tuple of str
        The files to write, ``.png`` and ``.svg`` by default (two processes may each
        draw one).

    Returns
    -------
    list of Path
        The files written.

    """
    title = (f'Allan deviation: {result.source or "input"}  ({result.n_samples} samples, '
             f'{result.duration_s / 3600:.2f} h at {result.rate_hz:.1f} Hz; dotted: white, '
             'bias, drift and periodic terms; dashed: beyond the fitted taus)')
    fig = adev_figure(result.curve, result.fits, title, figsize=(13, 5.2))
    return save_figure(fig, Path(base), tight=False, formats=formats)


def adev_rgb(curve, fits: dict, title: str, width_px: int = 1040,
             height_px: int = 416):
    """
    Render the ADEV figure as pixels (the node's ``~/adev_image``).

    Parameters
    ----------
    curve : imu_allan.core.allan.curve.AllanCurve
        The measured curve, with its confidence bounds.
    fits : dict
        Axis name -> AxisFit or None (empty before the first fit).
    title : str
        The figure's title.
    width_px, height_px : int
        The image size [pixel].

    Returns
    -------
    numpy.ndarray
        Shape (height_px, width_px, 3), uint8 RGB.

    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    dpi = 80.0
    fig = adev_figure(curve, fits, title, figsize=(width_px / dpi, height_px / dpi))
    _plain_log_labels(fig)
    canvas = FigureCanvasAgg(fig)
    fig.set_dpi(dpi)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[:, :, :3].copy()


#: The dotted lines of the figure: each term's group (the rest are "bias").
_GROUPS = {'white': 'white', 'filtered_white': 'white', 'quantization': 'white',
           'random_walk': 'drift', 'rate_ramp': 'drift', 'sinusoid': 'periodic'}
#: Where N, B and K are read on an ADEV curve (IEEE Std 952 C.1): the white line at
#: tau = 1 s, 0.664 B at the floor, the random-walk line at tau = 3 s.
_MARKS = {'N': '^', 'B': 's', 'K': 'v'}


def effect_group(term: str) -> str:
    """Return the group a term is drawn in: white, bias, drift or periodic."""
    return _GROUPS.get(term, 'bias')


def _envelope(avar: np.ndarray, width: int = 15) -> np.ndarray:
    """Upper envelope of a sinusoid's comb of nulls: the largest value in a moving window."""
    if avar.size < width:
        return avar
    padded = np.pad(avar, width // 2, mode='edge')
    return np.lib.stride_tricks.sliding_window_view(padded, width).max(axis=1)


def _mark_nbk(ax, fit, colour: str) -> None:
    """Mark where N, B and K are read, for the estimates (hollow: a bound)."""
    tau_lo, tau_hi = float(fit.tau_s.min()), float(fit.tau_s.max())
    for sym, marker in _MARKS.items():
        p = fit.optimised.get(sym)
        if p is None or not np.isfinite(p.value) or p.kind == 'not_identified':
            continue
        if sym == 'N':
            at = (1.0, p.value)
        elif sym == 'K':
            at = (3.0, p.value)
        else:
            t_b = fit.optimised.get('T_B')
            tau = 1.89 * t_b.value if t_b is not None and np.isfinite(t_b.value) else None
            if tau is None:
                i = int(np.argmin(fit.avar_meas))
                tau = float(fit.tau_s[i])
            at = (tau, 0.664 * p.value)
        if not tau_lo / 10 <= at[0] <= tau_hi * 10:
            continue
        ax.loglog(*at, marker, ms=7, color=colour, mec='black', mew=0.6,
                  mfc=colour if p.kind == 'estimate' else 'none')


def adev_figure(curve, fits: dict, title: str, figsize: tuple) -> Figure:
    """
    Build the ADEV figure: measured curves with bands, models and their terms.

    Parameters
    ----------
    curve : imu_allan.core.allan.curve.AllanCurve
        The measured curve, with its confidence bounds.
    fits : dict
        Axis name -> AxisFit or None; an axis without a fit shows its curve only.
    title : str
        The figure's title.
    figsize : tuple of float
        (width, height) [inch].

    Returns
    -------
    matplotlib.figure.Figure
        The figure, not yet saved.

    """
    tau = curve.tau_s
    tau_fine = np.geomspace(tau[0], tau[-1], 200)
    fig, panels = subplots(1, 2, figsize=figsize)
    for ax, (axes, ylabel) in zip(panels, _PANELS):
        cols = [AXES.index(a) for a in axes]
        lo_hi = curve.adev_lo[:, cols], curve.adev_hi[:, cols]
        shown = [np.nanmin(np.where(lo_hi[0] > 0, lo_hi[0], np.nan)),
                 np.nanmax(np.where(np.isfinite(lo_hi[1]), lo_hi[1], np.nan))]
        for axis in axes:
            j = AXES.index(axis)
            colour = _COLOURS[axis[-1]]
            ok = curve.avar[:, j] > 0
            if not ok.any():
                continue
            ax.fill_between(tau[ok], curve.adev_lo[ok, j], curve.adev_hi[ok, j],
                            color=colour, alpha=0.18, lw=0)
            ax.loglog(tau[ok], curve.adev[ok, j], 'o', ms=3, color=colour,
                      label=f'{axis} measured (95 % band)')
            fit = fits.get(axis)
            if fit is None:
                continue
            # The model where it was fitted, dashed where it extrapolates.
            lo, hi = fit.tau_s.min(), fit.tau_s.max()
            inside = (tau_fine >= lo * 0.999) & (tau_fine <= hi * 1.001)
            model = np.sqrt(fit.avar_at(tau_fine))
            ax.loglog(tau_fine[inside], model[inside], '-', color=colour, lw=1.4,
                      label=f'{axis} model')
            for part in (tau_fine < lo, tau_fine > hi):
                if part.any():
                    ax.loglog(tau_fine[part], model[part], '--', color=colour, lw=1.0,
                              alpha=0.7)
            # One dotted line per group of terms, not one per term: a comb of sinusoid
            # curves and a label per term hid the curve.
            groups: dict = {}
            for label, c_si, phi in fit.components:
                group = effect_group(base_name(label))
                avar = c_si * TERMS[base_name(label)].shape(tau_fine[inside], *phi)
                groups[group] = groups.get(group, 0.0) + avar
            for group, avar in groups.items():
                if group == 'periodic':
                    avar = _envelope(avar)
                ax.loglog(tau_fine[inside], np.sqrt(avar), ':', color=colour, lw=0.9,
                          alpha=0.7)
            _mark_nbk(ax, fit, colour)
        ax.set_xlabel('averaging time tau [s]')
        ax.set_ylabel(ylabel)
        ax.grid(True, which='major', alpha=0.3)
        if np.all(np.isfinite(shown)):
            # The measured curves set the range; a term far below them is cut off.
            ax.set_ylim(shown[0] / 30.0, shown[1] * 3.0)
        ax.legend(fontsize=6, loc='lower left')
    panels[0].plot([], [], 'k^', ms=6, label='N: white line at 1 s')
    panels[0].plot([], [], 'ks', ms=6, label='B: 0.664 B at the floor')
    panels[0].plot([], [], 'kv', ms=6, label='K: random-walk line at 3 s (hollow: a bound)')
    panels[0].legend(fontsize=6, loc='lower left')
    fig.suptitle(title, fontsize=10)
    # A fixed layout: every analysis draws this figure, and cropping costs a draw.
    fig.subplots_adjust(left=0.06, right=0.985, bottom=0.1, top=0.9, wspace=0.2)
    return fig


def plot_comparison(results: list, labels: list, base) -> list:
    """
    Overlay the measured ADEV of several recordings (run-to-run spread).

    Parameters
    ----------
    results : list of AnalysisResult
        One per input.
    labels : list of str
        Their names.
    base : str or Path
        Output path without suffix.

    Returns
    -------
    list of Path
        The PNG and SVG files.

    """
    fig, panels = subplots(2, 3, figsize=(15, 8), sharex=True)
    cmap = colormaps['viridis'].resampled(max(len(results), 2))
    for j, axis in enumerate(AXES):
        ax = panels[j // 3, j % 3]
        for k, (res, label) in enumerate(zip(results, labels)):
            c = res.curve
            ok = c.avar[:, j] > 0
            ax.fill_between(c.tau_s[ok], c.adev_lo[ok, j], c.adev_hi[ok, j],
                            color=cmap(k), alpha=0.12, lw=0)
            ax.loglog(c.tau_s[ok], c.adev[ok, j], '-', color=cmap(k), lw=1, label=label)
        ax.set_title(axis, fontsize=9)
        ax.grid(True, which='both', alpha=0.3)
        if j % 3 == 0:
            ax.set_ylabel('ADEV [rad/s]' if j < 3 else 'ADEV [m/s\u00b2]')
        if j >= 3:
            ax.set_xlabel('tau [s]')
    panels[0, 0].legend(fontsize=7)
    fig.suptitle('Run-to-run comparison of the Allan deviation (95 % bands)', fontsize=10)
    return save_figure(fig, Path(base))


def plot_diagnosis(diag, path) -> Path:
    """
    Paper-style figure of one axis' diagnosis (Maia et al. figures 2-5).

    Measured ADEV with its 95 % band, the simulated ADEV of the base model (before) and
    of the final model (after), and the tau bands where the base model disagrees beyond
    95 % shaded.

    Parameters
    ----------
    diag : imu_allan.core.diagnose.AxisDiagnosis
        The axis' diagnosis.
    path : str or Path
        The PNG file to write.

    Returns
    -------
    Path
        The file written.

    """
    path = Path(path)
    tau, adev, s = diag.tau_s, diag.adev, diag.s_ln
    fig, ax = subplots(1, 1, figsize=(6.4, 4.4))
    ax.fill_between(tau, adev * np.exp(-1.96 * s), adev * np.exp(1.96 * s), color='0.6',
                    alpha=0.35, lw=0, label='measured, 95 % band')
    ax.loglog(tau, adev, 'ko', ms=3.5, label='measured')
    ax.loglog(tau, diag.adev_before, '--', color='tab:red', lw=1.4,
              label=f'simulated base model (gap {diag.gap_before:.2g})')
    if diag.missing:
        added = ' + '.join(spoken(f.effect) for f in diag.missing)
        ax.loglog(tau, diag.adev_after, '-', color='tab:blue', lw=1.6,
                  label=f'simulated with {added} (gap {diag.gap_after:.2g})')
    for k, band in enumerate(diag.bands_before):
        lo, hi = band.tau_range_s
        ax.axvspan(lo / 1.2, hi * 1.2, color='tab:orange', alpha=0.15, lw=0,
                   label='disagreement (|z| > 2)' if k == 0 else None)
    ax.set_xlabel('averaging time tau [s]')
    ax.set_ylabel(f'ADEV [{diag.unit}]')
    ax.grid(True, which='both', alpha=0.3)
    ax.legend(fontsize=7, loc='best')
    # The whole summary, wrapped: a cut sentence hides the effects named last.
    ax.set_title('\n'.join(textwrap.wrap(diag.summary, 100)), fontsize=7)
    path.parent.mkdir(parents=True, exist_ok=True)
    _plain_log_labels(fig)
    fig.savefig(path, dpi=90, bbox_inches='tight')
    return path
