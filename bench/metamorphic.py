r"""
The clean record is the oracle: degrade real and simulated records, compare with the clean.

Usage (from the repository, ``../shared`` beside it for the real records)::

    nice -n 5 .venv/bin/python bench/metamorphic.py --inputs adis1,adis6,mpu,sim10,sim100,sim400 \
        --jobs 1 --out /tmp/meta.jsonl

Each input (ADIS16405 runs ``adis1``..``adis6``, the MPU-6050 record ``mpu``, seeded
simulations ``sim10``, ``sim100``, ``sim400`` at 10, 100 and 400 Hz) is degraded by
every class of :mod:`degrade` (``--degradations``) at each of its sizes (``--sizes``:
indices into the class' sizes), written as a CSV (with a ``temperature`` column where
the record has one) and analysed as ``imu-allan analyze --no-plan`` does
(:func:`imu_allan.io.inputs.analyze_input`, one process, no plan).  The clean
record's analysis is cached (``--cache``).

Per axis and parameter (N, B, K, T_B, as every output reports them: the ``reported``
section of result.json) the degraded analysis is one of:

- ``agree``: the reported intervals overlap (an upper bound is [0, bound], a lower bound
  [bound, inf], a parameter not identified makes no claim);
- ``warned``: they do not, but a top-level warning the clean record lacks names the axis
  (or its sensor, or no axis: the whole record; a short record's warning the parameter
  too) and the cause (a word of the class' ``cause``), or a warning of the clean record
  that does so states other figures (the coarse-resolution warning's raise of N on a
  record rounded coarser);
- ``flagged``: they do not, and a warning the clean record lacks is about the axis but
  names another cause (the "fit not trusted" warning, motion ...): the rule is not met;
- ``CONFIDENT``: they do not and no new warning is about the axis: a confident
  disagreement;

and per case ``REFUSED`` (an InputError on a usable record; a unit mistake refused with
its ``--units`` fix is ``warned``), ``over``: a reported bound (an upper bound of N, B or
K, or a consumer's white-noise / random-walk value taken at a bound) whose Allan
deviation lies above the record's own joint upper 95 % ADEV band at some tau the fit
reads (from its first fitted tau on: the shorter ones, flattened by the sensor's filter
or by held values, lie below the white line by construction; estimates above the band
are counted apart), and ``detected``: a top-level warning with a cause word that the clean
record does not have (the power).

Printed: a markdown table per degradation and size (counts over the inputs), then
every confident disagreement, refusal and value over its curve with its figures.
"""

import argparse
from concurrent.futures import ProcessPoolExecutor
import functools
import json
import math
import os
from pathlib import Path
import re
import subprocess
import sys
import tempfile
import time

# One BLAS thread, as the CLI and the node run; must precede the numpy import.
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

import numpy as np  # noqa: E402

# This checkout's package first (a script's sys.path[0] is bench/, and the venv's
# editable install may point at another checkout), then bench/ for degrade.
sys.path[:0] = [str(Path(__file__).resolve().parents[1]), str(Path(__file__).resolve().parent)]
from degrade import DEGRADATIONS, degrade, Record  # noqa: E402, I100

from imu_allan import AXES  # noqa: E402, I100
from imu_allan.core.allan.edf import avar_upper  # noqa: E402
from imu_allan.core.allan.hold import hold_bias, MAX_BIAS  # noqa: E402
from imu_allan.core.outputs.short_record import CONSUMER_NAMES, SHORT_RECORD  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
REALDATA = REPO.parent / 'shared' / 'realdata'
SYMBOLS = ('N', 'B', 'K', 'T_B')
#: A reported value's ADEV may exceed each point's own upper band by this factor before
#: it counts (information: a line through many points crosses one point's band by chance).
OVER_TOL = 1.1
#: ... and the joint band by this one: the floor bound divides by IEEE Std 952's 0.664,
#: which rounds the Gauss-Markov and flicker peaks (0.6643 B) down.
JOINT_TOL = 1.001
#: Seeded simulations: (rate [Hz], duration [s]).
SIMS = {'sim10': (10.0, 7200.0), 'sim100': (100.0, 1800.0), 'sim400': (400.0, 600.0)}


# --- inputs ----------------------------------------------------------------------------------

def sim_spec():
    """Return the NoiseSpec of the seeded simulations (MEMS-like, gravity on accel_z)."""
    from imu_allan.core.noise.values import AxisNoise, NoiseSpec
    gyro = {'N': 1.5e-4, 'B': 3e-5, 'T_B': 200.0, 'K': 1e-6}
    accel = {'N': 1e-3, 'B': 1e-4, 'T_B': 200.0, 'K': 2e-5}
    bias = {'accel_z': 9.80665}
    axes = {a: AxisNoise(**(gyro if a.startswith('gyro') else accel),
                         bias=bias.get(a, 0.01 if a.startswith('gyro') else 0.1))
            for a in AXES}
    return NoiseSpec(name='metamorphic simulation', axes=axes)


@functools.lru_cache(maxsize=4)
def load(name: str) -> Record:
    """
    Return the clean record of an input name (cached per process).

    ``NAME:MIN`` is the first MIN minutes of input NAME (e.g. ``adis6:60``).
    """
    from imu_allan.io.csv_io import read_csv
    if ':' in name:
        base, minutes = name.split(':')
        rec = load(base)
        keep = rec.t_s - rec.t_s[0] < float(minutes) * 60.0
        return rec._replace(t_s=rec.t_s[keep], samples=rec.samples[keep],
                            temp_c=None if rec.temp_c is None else rec.temp_c[keep])
    if name.startswith('adis'):
        d = read_csv(REALDATA / 'adis16405' / f'adis16405_run{name[4:]}.csv.gz',
                     columns=list(AXES))
        return Record(d.t_s, d.samples)
    if name == 'mpu':
        path = REALDATA / 'mpu6050_irregular' / 'mpu6050_static_11min.csv.gz'
        d = read_csv(path, columns=list(AXES) + ['temperature'])
        return Record(d.t_s, d.samples[:, :6], d.samples[:, 6].copy())
    if name in SIMS:
        from imu_allan.core.noise.simulate import simulate_imu
        rate_hz, duration_s = SIMS[name]
        t, y = simulate_imu(sim_spec(), rate_hz, duration_s, seed=int(rate_hz))
        return Record(t, y)
    raise SystemExit(f'unknown input {name!r}')


# --- one analysis ----------------------------------------------------------------------------

def write(rec: Record, path: Path) -> None:
    """Write a record as the CSV analyze reads (temperature column when present)."""
    from imu_allan.io.csv_io import write_csv
    if rec.temp_c is None:
        write_csv(path, rec.t_s, rec.samples, AXES)
    else:
        write_csv(path, rec.t_s, np.column_stack((rec.samples, rec.temp_c)),
                  list(AXES) + ['temperature'])


def _num(x) -> float | None:
    return float(x) if x is not None and math.isfinite(x) else None


def summarise(result) -> dict:
    """Return what the comparison needs of an AnalysisResult (plain JSON)."""
    axes = {}
    for j, axis in enumerate(AXES):
        fit = result.fits.get(axis)
        entry = {'tau_s': [float(x) for x in result.curve.tau_s],
                 'adev_hi': [_num(x) for x in result.curve.adev_hi[:, j]],
                 'adev': [_num(x) for x in result.curve.adev[:, j]],
                 'edf': [_num(x) for x in result.curve.edf[:, j]]}
        if fit is not None:
            rep = result.reports[axis]
            entry['params'] = {s: {'value': _num(p.value), 'lo': _num(p.ci95[0]),
                                   'hi': _num(p.ci95[1]), 'kind': p.kind}
                               for s, p in rep.params.items() if s in SYMBOLS}
            entry['white'] = [_num(rep.white.value), rep.white.kind]
            entry['random_walk'] = [_num(rep.random_walk.value), rep.random_walk.kind]
            entry['trusted'] = bool(fit.trusted)
            entry['fit_tau0_s'] = float(fit.tau_s[0]) if fit.tau_s.size else 0.0
            # Where the fit saw the sensor's filter end (a modelled filter's fit starts
            # at the bent taus, which lie below N's line).
            entry['white_tau0_s'] = max(entry['fit_tau0_s'], np.nan_to_num(fit.filter_end_s))
        entry['held'] = float(result.hygiene.get('held', {}).get(axis, 0.0))
        axes[axis] = entry
    return {'ok': True, 'warnings': list(result.warnings), 'n_samples': int(result.n_samples),
            'duration_s': float(result.duration_s), 'rate_hz': float(result.rate_hz),
            'axes': axes}


def analyse(rec: Record, declared: bool = False, workers: int = 1) -> dict:
    """
    Analyse a record as ``imu-allan analyze --no-plan`` does; return its summary.

    ``workers``: processes for the axes' searches (the sweep runs cases in parallel
    instead, ``--jobs``).
    """
    from imu_allan.core.noise.unit_check import parse_units
    from imu_allan.errors import InputError
    from imu_allan.io.inputs import analyze_input
    from imu_allan.pipeline.hygiene import SessionConfig
    units = parse_units(rec.units if declared else '')
    config = SessionConfig(units_declared=','.join(units.declared))
    start = time.monotonic()
    with tempfile.TemporaryDirectory(prefix='imu_meta_') as tmp:
        path = Path(tmp) / 'record.csv'
        write(rec, path)
        try:
            result, _ = analyze_input(path, None, config, quiet=True, progress=False,
                                      workers=workers, prefetch=False,
                                      units=None if units.is_si and not units.declared
                                      else units)
        except InputError as exc:
            return {'ok': False, 'error': type(exc).__name__,
                    'message': str(exc).replace(str(path), '<csv>'),
                    'seconds': time.monotonic() - start}
        except Exception as exc:  # noqa: B902 - a crash is a finding, the sweep goes on
            return {'ok': False, 'error': 'CRASH ' + type(exc).__name__, 'message': str(exc),
                    'seconds': time.monotonic() - start}
    out = summarise(result)
    out['seconds'] = time.monotonic() - start
    return out


# --- comparison ------------------------------------------------------------------------------

def interval(p: dict | None) -> tuple | None:
    """Return the (lo, hi) a reported parameter claims, None when it claims nothing."""
    if p is None or p['value'] is None:
        return None
    if p['kind'] == 'estimate':
        lo = p['lo'] if p['lo'] is not None else p['value']
        hi = p['hi'] if p['hi'] is not None else math.inf
        return lo, hi
    if p['kind'] == 'upper_bound':
        return 0.0, p['value']
    if p['kind'] == 'lower_bound':    # the 95 % statement: its interval's lower end
        return (p['lo'] if p['lo'] is not None else p['value']), math.inf
    return None


def names_axis(warning: str, axis: str) -> bool:
    """Tell whether a warning is about an axis: names it, its sensor, or no axis at all."""
    w = warning.lower()
    sensor = axis.split('_')[0]
    named = [a for a in AXES if a in w]
    if axis in w:
        return True
    if not named and (sensor in w or ('gyro' not in w and 'accel' not in w)):
        return True
    return False


def names_param(warning: str, axis: str, sym: str) -> bool:
    """Tell whether a warning can be about a parameter: one of a short record names it."""
    if not warning.startswith(SHORT_RECORD):
        return True
    name = CONSUMER_NAMES.get((axis.split('_')[0], sym))
    return name is not None and name in warning


def _shape(warning: str) -> str:
    """Return a warning with its numbers blanked (the same warning at other figures)."""
    return re.sub(r'[-+]?\d[\d.,]*(e[-+]?\d+)?', '#', warning)


def has_cause(warning: str, cause: tuple) -> bool:
    """Tell whether a warning names one of the cause words."""
    w = warning.lower()
    return any(c in w for c in cause)


def _term_adev(sym: str, value: float, tau: np.ndarray, t_b: float | None) -> np.ndarray:
    """ADEV of one term at its reported value [unit] (IEEE Std 952 C.1 slopes)."""
    if sym == 'N':
        return value / np.sqrt(tau)
    if sym == 'K':
        return value * np.sqrt(tau / 3.0)
    from imu_allan.core.noise.model import avar_model
    from imu_allan.core.noise.values import AxisNoise
    return np.sqrt(avar_model(tau, AxisNoise(B=value, T_B=t_b)))


def over_curve(entry: dict, kinds: tuple = ('upper_bound', 'curve_bound'),
               joint: bool = True) -> list:
    """
    Return [(what, kind, worst ratio, tau)] of reported values above the upper band.

    ``kinds``: which values count: bounds by default (an estimate's line may cross one
    point's band by chance where the fit rests on many points).  ``joint``: the band is
    the curve's joint 95 % upper limit (Bonferroni over the points,
    :func:`imu_allan.core.allan.edf.avar_upper`, what a bound read off the whole curve
    must respect); else each point's own 95 % band, which a line through many points
    crosses somewhere by chance (reported beside it, not a failure).
    """
    if 'params' not in entry or 'tau_s' not in entry:
        return []
    tau = np.asarray(entry['tau_s'], dtype=np.float64)
    # The taus the fit reads: the shorter ones, flattened by the sensor's filter or by
    # held values, lie below the white line by construction.
    read = tau >= entry.get('fit_tau0_s', 0.0) * (1.0 - 1e-9)
    # A held axis' curve is read corrected for the hold (core.allan.hold), as the fit does.
    held = entry.get('held', 0.0)
    bias = hold_bias(tau / tau[0], 1.0 / (1.0 - held)) if held else np.zeros(tau.size)
    gain = 1.0 / np.sqrt(1.0 - np.minimum(bias, MAX_BIAS))
    if joint:
        adev = np.array([np.nan if v is None else v for v in entry['adev']])
        edf = np.array([np.nan if v is None else v for v in entry['edf']])
        ok = np.isfinite(adev) & np.isfinite(edf) & (edf > 0) & read
        tau = tau[ok]
        hi = np.sqrt(avar_upper(adev[ok] ** 2, edf[ok])) * gain[ok]
    else:
        hi = np.array([np.nan if v is None else v for v in entry['adev_hi']])
        hi = np.where(read, hi * gain, np.nan)
    ok = np.isfinite(hi) & (hi > 0)
    if not ok.any():
        return []
    tau, hi = tau[ok], hi[ok]
    t_b = entry['params'].get('T_B', {})
    t_b = t_b.get('value') if t_b.get('kind') in ('estimate', 'lower_bound') else None
    values = [(s, p['value'], p['kind']) for s, p in entry['params'].items()
              if s in ('N', 'B', 'K') and p['kind'] in kinds and p['value']]
    values += [(f'consumer {s}', entry[key][0], entry[key][1])
               for s, key in (('N', 'white'), ('K', 'random_walk'))
               if entry[key][0] and entry[key][1] in kinds]
    out = []
    white = tau >= entry.get('white_tau0_s', 0.0) * (1.0 - 1e-9)
    for what, value, kind in values:
        sym = what.split()[-1]
        ratio = _term_adev(sym, value, tau, t_b) / hi
        if sym == 'N':
            ratio = np.where(white, ratio, 0.0)
        k = int(np.argmax(ratio))
        if ratio[k] > (JOINT_TOL if joint else OVER_TOL):
            out.append((what, kind, float(ratio[k]), float(tau[k])))
    return out


def compare(clean: dict, degraded: dict, deg_name: str) -> dict:
    """Classify one degraded analysis against the clean one (the module docstring)."""
    deg_key = deg_name.split('+')[0]
    cause = DEGRADATIONS[deg_key].cause
    if deg_name.endswith('+declared'):
        # The units declared, what is left is the record's first minutes (the size).
        cause = DEGRADATIONS['first_minutes'].cause
    if not degraded['ok']:
        unit_refusal = (degraded['error'] == 'UnitMistake'
                        and DEGRADATIONS[deg_key].declared and not deg_name.endswith('+declared'))
        return {'outcome': 'warned' if unit_refusal else 'REFUSED',
                'message': degraded['message'][:300], 'cells': {}, 'over': [],
                'detected': unit_refusal}
    before = {_shape(w) for w in clean['warnings']}
    new = [w for w in degraded['warnings'] if _shape(w) not in before]
    # A warning of the clean record at other figures names the degradation's effect
    # where it names its cause (rounding raises N by 6 % where the clean record's 1 %).
    restated = [w for w in degraded['warnings']
                if _shape(w) in before and w not in clean['warnings'] and has_cause(w, cause)]
    detected = any(has_cause(w, cause) for w in new)
    cells = {}
    for axis in AXES:
        c, d = clean['axes'][axis].get('params', {}), degraded['axes'][axis].get('params', {})
        for sym in SYMBOLS:
            ci, di = interval(c.get(sym)), interval(d.get(sym))
            if ci is None or di is None or (ci[0] <= di[1] and di[0] <= ci[1]):
                cells[f'{axis} {sym}'] = 'agree'
                continue
            about = [w for w in new if names_axis(w, axis) and names_param(w, axis, sym)]
            if any(has_cause(w, cause) for w in about + restated
                   if names_axis(w, axis) and names_param(w, axis, sym)):
                cells[f'{axis} {sym}'] = 'warned'
            else:
                cells[f'{axis} {sym}'] = 'flagged' if about else 'CONFIDENT'
    over = [(axis, *o) for axis in AXES for o in over_curve(degraded['axes'][axis])]
    over_est = [(axis, *o) for axis in AXES
                for o in over_curve(degraded['axes'][axis], ('estimate',))]
    return {'outcome': 'analysed', 'cells': cells, 'over': over, 'over_estimates': over_est,
            'detected': detected}


# --- the sweep -------------------------------------------------------------------------------

def _commit() -> str:
    try:
        out = subprocess.run(['git', 'describe', '--always', '--dirty'], cwd=REPO,
                             capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        out = 'unknown'
    return out


def _package_tree() -> str:
    """Return the git tree hash of imu_allan/ ('dirty' when it has local changes)."""
    def git(*cmd):
        return subprocess.run(['git', *cmd], cwd=REPO, capture_output=True, text=True,
                              check=True).stdout.strip()
    try:
        return 'dirty' if git('status', '--porcelain', 'imu_allan') else \
            git('rev-parse', 'HEAD:imu_allan')[:12]
    except (OSError, subprocess.CalledProcessError):
        return 'dirty'


def clean_summary(name: str, cache: Path | None) -> dict:
    """Return the clean record's analysis, cached per state of the package's code."""
    key = f'{name}-{_package_tree()}.json'
    if cache is not None and 'dirty' not in key and (cache / key).exists():
        return json.loads((cache / key).read_text())
    out = analyse(load(name))
    if cache is not None and out['ok']:
        cache.mkdir(parents=True, exist_ok=True)
        (cache / key).write_text(json.dumps(out))
    return out


def run_case(job: tuple) -> dict:
    """Degrade, analyse and compare one (input, degradation, size, declared) case."""
    name, deg, size, declared, clean, seed = job
    rec = degrade(load(name), deg, size, seed=seed)
    degraded = analyse(rec, declared=declared)
    label = deg + ('+declared' if declared else '')
    verdict = compare(clean, degraded, label)
    return {'input': name, 'degradation': label, 'size': size, 'seconds': degraded['seconds'],
            'n_samples': degraded.get('n_samples'), 'warnings': degraded.get('warnings', []),
            'values': {a: degraded['axes'][a].get('params') for a in AXES}
            if degraded['ok'] else {}, **verdict}


def jobs_for(inputs: list, degradations: list, size_index: list, clean: dict,
             seed: int) -> list:
    """Return every case of the sweep, declared-unit variants included."""
    jobs = []
    for name in inputs:
        if not clean[name]['ok']:
            continue
        for deg in degradations:
            d = DEGRADATIONS[deg]
            for k in size_index:
                if k >= len(d.sizes):
                    continue
                jobs.append((name, deg, d.sizes[k], False, clean[name], seed))
                if d.declared:
                    jobs.append((name, deg, d.sizes[k], True, clean[name], seed))
    return jobs


# --- reporting -------------------------------------------------------------------------------

COLUMNS = ('agree', 'warned', 'flagged', 'CONFIDENT')


def table(rows: list) -> str:
    """Return the markdown table: counts per degradation and size over the inputs."""
    groups: dict = {}
    for r in rows:
        groups.setdefault((r['degradation'], r['size']), []).append(r)
    order = {n: i + 1 for i, n in enumerate(DEGRADATIONS)}
    order['clean'] = 0
    lines = ['| degradation | size | inputs | detected | refused | axis-params agree / '
             'warned / flagged / **confident** | bounds over curve | estimates over curve |',
             '|---|---|---|---|---|---|---|---|']
    for (deg, size), rs in sorted(groups.items(), key=lambda kv: (
            order[kv[0][0].split('+')[0]], kv[0][0], kv[0][1])):
        unit = DEGRADATIONS[deg.split('+')[0]].size_unit if deg != 'clean' else ''
        counts = {c: sum(v == c for r in rs for v in r['cells'].values()) for c in COLUMNS}
        refused = sum(r['outcome'] == 'REFUSED' for r in rs)
        unit_refused = sum(r['outcome'] == 'warned' for r in rs)
        detected = sum(bool(r['detected']) for r in rs)
        over = sum(len(r['over']) for r in rs)
        worst = max((o[3] for r in rs for o in r['over']), default=0.0)
        over_est = sum(len(r.get('over_estimates', [])) for r in rs)
        conf = counts['CONFIDENT']
        lines.append(f'| {deg} | {size:g} {unit} | {len(rs)} | {detected}/{len(rs)} | '
                     f'{refused}' + (f' (+{unit_refused} unit)' if unit_refused else '')
                     + f' | {counts["agree"]} / {counts["warned"]} / {counts["flagged"]} / '
                     + (f'**{conf}**' if conf else '0') + f' | {over}'
                     + (f' (up to {worst:.3g}x)' if over else '') + f' | {over_est} |')
    return '\n'.join(lines) + '\n'


def verdicts(rows: list) -> dict:
    """
    Return one word per degradation class over all its rows (inputs and sizes).

    'not yet' (a confident disagreement or a refusal), 'flagged' (a disagreement whose
    warning does not name the cause), else 'handled'; with the counts behind it.
    """
    out = {}
    for name in DEGRADATIONS:
        rs = [r for r in rows if r['degradation'].split('+')[0] == name]
        if not rs:
            continue
        conf = sum(v == 'CONFIDENT' for r in rs for v in r['cells'].values())
        flag = sum(v == 'flagged' for r in rs for v in r['cells'].values())
        warned = sum(v == 'warned' for r in rs for v in r['cells'].values())
        refused = sum(r['outcome'] == 'REFUSED' for r in rs)
        # Declared units must agree, not warn: the power is over the records as written.
        asis = [r for r in rs if not r['degradation'].endswith('+declared')]
        detected = sum(bool(r['detected']) for r in asis)
        word = 'not yet' if conf or refused else 'flagged' if flag else 'handled'
        parts = [f'{conf} confident'] if conf else []
        parts += [f'{refused} refused'] if refused else []
        parts += [f'{flag} flagged'] if flag else []
        parts += [f'{warned} warned'] if warned else []
        out[name] = f'**{word}**' + (f' ({", ".join(parts)})' if parts else '') + \
            f'; detected in {detected}/{len(asis)}'
    return out


def _fmt(p: dict | None) -> str:
    if p is None or p.get('value') is None:
        return 'n/a'
    if p['kind'] == 'estimate':
        return f'{p["value"]:.3g} [{_g(p["lo"])}, {_g(p["hi"])}]'
    if p['kind'] == 'lower_bound' and p['lo'] is not None:
        return f'> {p["lo"]:.3g} (fit {p["value"]:.3g})'
    return {'upper_bound': '< ', 'lower_bound': '> '}.get(p['kind'], '? ') + f'{p["value"]:.3g}'


def _g(x) -> str:
    return 'inf' if x is None else f'{x:.3g}'


def _z(a: dict | None, b: dict | None) -> float:
    """
    Return how far apart two estimates are in their combined sd (log scale), or NaN.

    Each 95 % interval gives sd ln(hi / lo) / 3.92 (a log-normal reading); with the two
    taken independent, |z| > 1.96 for ~5 % of pairs of the same truth, 3.9 for 1e-4.
    """
    vals = [(x['value'], x['lo'], x['hi']) for x in (a, b) if x and x.get('kind') == 'estimate'
            and x['lo'] and x['hi'] and x['value']]
    if len(vals) < 2 or min(v for t in vals for v in t) <= 0:
        return math.nan
    sd = [math.log(hi / lo) / 3.92 for _, lo, hi in vals]
    return abs(math.log(vals[0][0] / vals[1][0])) / math.hypot(*sd)


def findings(rows: list, clean: dict) -> str:
    """Return every confident disagreement, refusal and value over its curve."""
    out = []
    for r in rows:
        tag = f'{r["input"]} {r["degradation"]} {r["size"]:g}'
        if r['outcome'] == 'REFUSED':
            out.append(f'- REFUSED {tag}: {r["message"]}')
        for cell, v in r['cells'].items():
            if v != 'CONFIDENT':
                continue
            axis, sym = cell.split()
            c = clean[r['input']]['axes'][axis]['params'].get(sym)
            d = r['values'][axis].get(sym)
            ratio = (d['value'] / c['value'] if c and d and c['value'] and d['value']
                     else math.nan)
            out.append(f'- CONFIDENT {tag}: {axis} {sym} clean {_fmt(c)}, degraded {_fmt(d)} '
                       f'(x{ratio:.3g}, z {_z(c, d):.2g})')
        for axis, what, kind, ratio, tau in r['over']:
            out.append(f'- OVER {tag}: {axis} {what} ({kind}) {ratio:.3g}x the upper ADEV band '
                       f'at tau {tau:.3g} s')
    return '\n'.join(out) + '\n'


def clean_rows(clean: dict) -> list:
    """Return a row per clean record: refused, or bounds over its own curve."""
    return [{'input': name, 'degradation': 'clean', 'size': 0.0, 'detected': False,
             'cells': {}, 'outcome': 'analysed' if c['ok'] else 'REFUSED',
             'message': c.get('message', ''),
             'over': [(a, *o) for a in AXES for o in over_curve(c['axes'][a])]
             if c['ok'] else [],
             'over_estimates': [(a, *o) for a in AXES
                                for o in over_curve(c['axes'][a], ('estimate',))]
             if c['ok'] else []} for name, c in clean.items()]


def report(paths: list, cache: Path) -> None:
    """Print the table and findings of earlier runs (their clean analyses from the cache)."""
    rows = [json.loads(line) for p in paths for line in p.read_text().splitlines() if line]
    # One row per case: a case run again (a later file) replaces the earlier one.
    rows = list({(r['input'], r['degradation'], r['size']): r for r in rows}.values())
    names = sorted({r['input'] for r in rows})
    clean = {}
    for name in names:
        found = sorted(cache.glob(f'{name}-*.json'), key=lambda p: p.stat().st_mtime)
        clean[name] = json.loads(found[-1].read_text())
    for r in rows:     # judged again by this code (the bounds over curve as stored)
        if r['outcome'] == 'analysed':
            again = compare(clean[r['input']], {'ok': True, 'warnings': r['warnings'], 'axes': {
                a: {'params': r['values'][a]} if r['values'][a] else {} for a in AXES}},
                r['degradation'])
            r['cells'], r['detected'] = again['cells'], again['detected']
    rows = clean_rows(clean) + rows
    print(f'### Metamorphic bench: {len(rows) - len(names)} cases, inputs {", ".join(names)}\n')
    print(table(rows))
    print('### Per class\n')
    for name, text in verdicts(rows).items():
        print(f'- {name}: {text}')
    print('\n### Findings\n')
    print(findings(rows, clean))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--inputs', '--runs', default='adis1,adis6,mpu,sim10,sim100,sim400',
                        help='comma-separated: adis1..adis6, mpu, sim10, sim100, sim400')
    parser.add_argument('--degradations', default=','.join(DEGRADATIONS),
                        help='comma-separated class names (default: all)')
    parser.add_argument('--sizes', default='0,1,2',
                        help="indices into each class' sizes, smallest first (default 0,1,2)")
    parser.add_argument('--jobs', type=int, default=1, help='worker processes (default 1)')
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--cache', type=Path,
                        default=Path(tempfile.gettempdir()) / 'imu_allan_metamorphic',
                        help='where clean analyses are kept (per commit)')
    parser.add_argument('--out', type=Path, default=None, help='write every case as JSON lines')
    parser.add_argument('--report', type=Path, nargs='*', default=None, metavar='JSONL',
                        help='only print the table of earlier --out files (clean from --cache)')
    args = parser.parse_args()
    if args.report is not None:
        report(args.report, args.cache)
        return
    inputs = [s for s in args.inputs.split(',') if s]
    degradations = [s for s in args.degradations.split(',') if s]
    unknown = [d for d in degradations if d not in DEGRADATIONS]
    if unknown:
        raise SystemExit(f'unknown degradations {unknown}; known: {", ".join(DEGRADATIONS)}')
    size_index = [int(s) for s in args.sizes.split(',') if s]
    started = time.monotonic()
    clean = {name: clean_summary(name, args.cache) for name in inputs}
    for name, c in clean.items():
        if not c['ok']:
            print(f'clean {name} REFUSED: {c["message"]}', file=sys.stderr)
    jobs = jobs_for(inputs, degradations, size_index, clean, args.seed)
    print(f'{len(jobs)} cases on {len(inputs)} inputs, commit {_commit()}', file=sys.stderr)
    # The clean records themselves: refused, or a value over their own curve.
    rows = clean_rows(clean)
    sink = args.out.open('w') if args.out else None
    pool = ProcessPoolExecutor(args.jobs) if args.jobs > 1 else None
    results = pool.map(run_case, jobs) if pool else map(run_case, jobs)
    for k, row in enumerate(results):
        rows.append(row)
        if sink:
            sink.write(json.dumps(row) + '\n')
            sink.flush()
        conf = sum(v == 'CONFIDENT' for v in row['cells'].values())
        print(f'[{k + 1}/{len(jobs)}] {row["input"]} {row["degradation"]} {row["size"]:g}: '
              f'{row["outcome"]} confident {conf} over {len(row["over"])} '
              f'detected {row["detected"]} ({row["seconds"]:.0f} s)', file=sys.stderr,
              flush=True)
    if pool:
        pool.shutdown()
    print(f'\n### Metamorphic bench: {len(rows)} cases, inputs {", ".join(inputs)}, commit '
          f'{_commit()}, {time.monotonic() - started:.0f} s\n')
    print(table(rows))
    print('### Findings\n')
    print(findings(rows, clean))


if __name__ == '__main__':
    main()
