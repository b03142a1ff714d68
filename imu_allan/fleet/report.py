"""
The fleet report: what failed, which IMUs changed or stand out, and plots of both.

Files written to the report directory:

* ``fleet.json``: inputs, failures, changes, outliers and the spread table;
* ``fleet_report.md``: the same as tables, for a person;
* ``fleet_<param>.png`` / ``.svg``: per axis, each IMU's latest value with its 95 %
  interval, by model, outliers marked (the fleet's distribution);
* ``trend_<param>.png`` / ``.svg``: per axis, every IMU's value relative to its first
  night over time, the nights that moved marked (the per-IMU trends).
"""

import json
import math
from pathlib import Path

import numpy as np

from imu_allan import AXES
from imu_allan.atomic import write_atomic
from imu_allan.errors import InputError
from imu_allan.fleet.views import by_imu, changes, estimate, fleet_spread, VIEW_PARAMS


def _time(start_ns: int) -> str:
    if start_ns is None or start_ns < 0:
        return '?'
    return np.datetime64(int(start_ns), 'ns').astype('datetime64[s]').astype(str)


def fleet_summary(rows: list[dict]) -> dict:
    """
    Return the fleet views of the store rows as one JSON-able dict.

    Returns
    -------
    dict
        'inputs' (counts), 'imus', 'failures' (path, reason), 'changes', 'outliers',
        'spread' (per model, axis and parameter).

    """
    ok = [r for r in rows if r['status'] == 'ok']
    failed = [r for r in rows if r['status'] == 'failed']
    spread = fleet_spread(rows)
    moved = changes(rows)
    return {
        'inputs': {'ok': len({r['key'] for r in ok}), 'failed': len(failed),
                   'messages': int(sum(r['n_samples'] for r in ok if r['axis'] == AXES[0]))},
        'imus': {imu: {'model': rs[0]['model'], 'nights': len({r['key'] for r in rs})}
                 for imu, rs in by_imu(rows).items()},
        'failures': [{'path': r['path'], 'reason': r['reason']} for r in failed],
        'changes': [dict(c._asdict(), start=_time(c.start_ns)) for c in moved],
        'outliers': [o._asdict() for s in spread for o in s.outliers],
        'spread': [dict(s._asdict(), outliers=[o.imu_id for o in s.outliers])
                   for s in spread],
    }


def _markdown(summary: dict) -> str:
    n = summary['inputs']
    lines = ['# Fleet report (imu_allan)', '',
             f'{n["ok"]} recordings analysed ({n["messages"]:,} messages), {n["failed"]} '
             f'failed; {len(summary["imus"])} IMUs.', '']
    if summary['failures']:
        lines += ['## Failed inputs', '', '| input | reason |', '| --- | --- |']
        lines += [f'| {f["path"]} | {f["reason"]} |' for f in summary['failures']] + ['']
    lines += ['## IMUs that changed', '']
    if summary['changes']:
        lines += ['| IMU | axis | param | night | ratio | z |', '| --- | --- | --- | --- | ---: '
                  '| ---: |']
        lines += [f'| {c["imu_id"]} | {c["axis"]} | {c["param"]} | {c["start"]} | '
                  f'{c["ratio"]:.3f} | {c["z"]:.1f} |' for c in summary['changes']]
    else:
        lines.append("None: every night lies within its IMU's intervals.")
    lines += ['', '## Outliers of their model', '']
    if summary['outliers']:
        lines += ['| IMU | model | axis | param | value | fleet median | z |',
                  '| --- | --- | --- | --- | ---: | ---: | ---: |']
        lines += [f'| {o["imu_id"]} | {o["model"]} | {o["axis"]} | {o["param"]} | '
                  f'{o["value"]:.4g} | {o["fleet_median"]:.4g} | {o["z"]:.1f} |'
                  for o in summary['outliers']]
    else:
        lines.append('None.')
    lines += ['', '## Spread per model (latest night of each IMU)', '',
              '| model | axis | param | IMUs | median | spread |', '| --- | --- | --- | ---: '
              '| ---: | ---: |']
    lines += [f'| {s["model"]} | {s["axis"]} | {s["param"]} | {s["n_imus"]} | '
              f'{s["median"]:.4g} | {100 * s["spread_rel"]:.1f} % |' for s in summary['spread']]
    return '\n'.join(lines) + '\n'


def _plot_fleet(rows: list[dict], param: str, base: Path) -> list:
    from imu_allan.io.plot import save_figure, subplots

    latest: dict = {}
    for r in by_imu(rows).values():
        for row in r:
            latest[(row['imu_id'], row['axis'])] = row
    imus = sorted({imu for imu, _ in latest})
    fig, axes = subplots(2, 3, figsize=(12, 6.5), squeeze=False)
    for ax, axis in zip(axes.ravel(), AXES):
        for i, imu in enumerate(imus):
            found = latest.get((imu, axis))
            if found is None or estimate(found, param) is None:
                continue
            v, lo, hi = found[param], found[f'{param}_lo'], found[f'{param}_hi']
            ax.errorbar([i], [v], yerr=[[v - lo], [hi - v]], fmt='o', ms=3, color='tab:blue')
        ax.set_yscale('log')
        ax.set_title(f'{axis}: {param}', fontsize=9)
        ax.set_xticks(range(len(imus)))
        ax.set_xticklabels(imus, rotation=90, fontsize=6)
    for s in fleet_spread(rows, params=(param,)):
        ax = axes.ravel()[AXES.index(s.axis)]
        ax.axhline(s.median, color='grey', lw=0.8)
        for o in s.outliers:
            ax.plot([imus.index(o.imu_id)], [o.value], 'o', mfc='none', mec='tab:red', ms=9)
    fig.suptitle(f'{param} of every IMU (latest night, 95 % intervals; red: outlier)')
    return save_figure(fig, base)


def _plot_trend(rows: list[dict], param: str, base: Path) -> list:
    from imu_allan.io.plot import save_figure, subplots

    moved = {(c.imu_id, c.axis, c.path) for c in changes(rows, params=(param,))}
    stamps = [r['start_ns'] for r in rows if r['status'] == 'ok' and r['start_ns'] >= 0]
    t0 = min(stamps) if stamps else 0
    fig, axes = subplots(2, 3, figsize=(12, 6.5), squeeze=False, sharex=True)
    for ax, axis in zip(axes.ravel(), AXES):
        for imu, imu_rows in by_imu(rows).items():
            pts = [((r['start_ns'] - t0) / 86400e9, r[param], r['path']) for r in imu_rows
                   if r['axis'] == axis and r['start_ns'] >= 0
                   and estimate(r, param) is not None]
            if not pts:
                continue
            t, v, paths = zip(*pts)
            rel = np.asarray(v) / v[0]
            ax.plot(t, rel, '.-', lw=0.8, ms=3)
            for ti, ri, p in zip(t, rel, paths):
                if (imu, axis, p) in moved:
                    ax.plot([ti], [ri], 'o', mfc='none', mec='tab:red', ms=8)
        ax.axhline(1.0, color='grey', lw=0.8)
        ax.set_title(f'{axis}: {param} / first night', fontsize=9)
    for ax in axes[-1]:
        ax.set_xlabel(f'days since {_time(t0)}', fontsize=8)
    fig.suptitle(f'{param} of each IMU over time (red: moved beyond its intervals)')
    return save_figure(fig, base)


def write_fleet_report(rows: list[dict], out, plot: bool = True) -> list[Path]:
    """
    Write fleet.json, fleet_report.md and (``plot``) the figures to ``out``.

    Returns
    -------
    list of Path
        The files written.

    Raises
    ------
    InputError
        Nothing in the store, or the directory cannot be written.

    """
    if not rows:
        raise InputError('the store holds no results yet')
    out = Path(out)
    summary = fleet_summary(rows)
    try:
        out.mkdir(parents=True, exist_ok=True)
        text = json.dumps(json_finite(summary), indent=1, allow_nan=False)
        paths = [write_atomic(out / 'fleet.json', lambda f: f.write(text), mode='w')]
        md = _markdown(summary)
        paths.append(write_atomic(out / 'fleet_report.md', lambda f: f.write(md), mode='w'))
        if plot:
            for param in VIEW_PARAMS:
                paths += _plot_fleet(rows, param, out / f'fleet_{param}')
                paths += _plot_trend(rows, param, out / f'trend_{param}')
    except OSError as exc:
        raise InputError(f'cannot write the report to {out}: {exc.strerror or exc}') from None
    return paths


def json_finite(obj):
    """Return obj with NaN and inf replaced by None (strict JSON), numpy scalars as Python."""
    if isinstance(obj, dict):
        return {k: json_finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_finite(v) for v in obj]
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    return obj
