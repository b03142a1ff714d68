"""
Fleet views: the spread across IMUs of one model, and each IMU against its own history.

Both work on log values and use each estimate's 95 % interval as its uncertainty:
sigma = (ln hi - ln lo) / (2 z95).  Only estimates count (upper bounds and terms the
record cannot identify say nothing about a change).

* **Spread** (:func:`fleet_spread`): per model, axis and parameter, the latest night of
  every IMU; the fleet's centre is the median of the log values and its spread
  1.4826 MAD (robust to the outliers being looked for).  An IMU is an outlier when
  z = (x - centre) / sqrt(spread^2 + sigma^2) exceeds :data:`OUTLIER_Z`: a value far from
  its siblings *given its own interval*, so a short noisy night is not flagged.
* **Change** (:func:`changes`): nights of one IMU in time order; the reference is the
  inverse-variance mean of the earlier nights not flagged.  A night moved when
  z = (x - ref) / sqrt(sigma^2 + sigma_ref^2) exceeds :data:`CHANGE_Z` *and* the ratio
  differs from 1 by :data:`MIN_CHANGE` or more (very long nights have intervals so narrow
  that the temperature of the dock would count as a change).
"""

from collections import defaultdict
import math
from typing import NamedTuple

import numpy as np

from imu_allan import AXES

Z95 = 1.959963984540054
#: |z| above which an IMU is an outlier of its model's fleet.
OUTLIER_Z = 4.0
#: |z| above which a night moved from its IMU's reference.
CHANGE_Z = 4.0
#: Smallest relative change reported as a change.
MIN_CHANGE = 0.1
#: IMUs of one model needed before outliers are named.
MIN_SIBLINGS = 4
#: Parameters the views look at.
VIEW_PARAMS = ('N', 'B', 'K')


class Estimate(NamedTuple):
    """One estimate in log units: x = ln(value), sigma from its 95 % interval."""

    x: float
    sigma: float


def estimate(row: dict, param: str) -> Estimate | None:
    """Return the log estimate of a parameter in a store row, or None if not an estimate."""
    v, lo, hi = row.get(param), row.get(f'{param}_lo'), row.get(f'{param}_hi')
    if row.get(f'{param}_kind') != 'estimate' or v is None or not (
            v > 0 and lo is not None and hi is not None and 0 < lo <= v <= hi
            and math.isfinite(hi)):
        return None
    return Estimate(math.log(v), max((math.log(hi) - math.log(lo)) / (2.0 * Z95), 1e-12))


def _night_order(row: dict) -> tuple:
    return (row['start_ns'] if row['start_ns'] >= 0 else math.inf, row['path'])


def by_imu(rows: list[dict]) -> dict[str, list[dict]]:
    """Group the analysed rows by IMU, each IMU's rows in time order."""
    out: dict[str, list[dict]] = defaultdict(list)
    for r in rows:
        if r['status'] == 'ok':
            out[r['imu_id']].append(r)
    return {k: sorted(v, key=_night_order) for k, v in sorted(out.items())}


class Outlier(NamedTuple):
    """An IMU whose latest value stands out of its model's fleet."""

    imu_id: str
    model: str
    axis: str
    param: str
    value: float
    fleet_median: float
    z: float
    key: str


class Spread(NamedTuple):
    """The spread of one parameter of one axis across the IMUs of one model."""

    model: str
    axis: str
    param: str
    n_imus: int
    median: float
    spread_rel: float
    outliers: tuple


def fleet_spread(rows: list[dict], params=VIEW_PARAMS, z_limit: float = OUTLIER_Z,
                 min_siblings: int = MIN_SIBLINGS) -> list[Spread]:
    """
    Return the spread of each model, axis and parameter over each IMU's latest night.

    Parameters
    ----------
    rows : list of dict
        Store rows.
    params : sequence of str
        Parameters to compare.
    z_limit : float
        Outlier threshold (see the module doc).
    min_siblings : int
        Fewer IMUs of a model give no outliers (the centre is not known well enough).

    Returns
    -------
    list of Spread

    """
    latest: dict[tuple, dict] = {}
    for r in sorted((r for r in rows if r['status'] == 'ok'), key=_night_order):
        latest[(r['model'], r['imu_id'], r['axis'])] = r
    out = []
    models = sorted({m for m, _, _ in latest})
    for model in models:
        for axis in AXES:
            for param in params:
                got = [(imu, r, e) for (m, imu, a), r in latest.items()
                       if m == model and a == axis
                       and (e := estimate(r, param)) is not None]
                if not got:
                    continue
                x = np.array([e.x for _, _, e in got])
                centre = float(np.median(x))
                spread = 1.4826 * float(np.median(np.abs(x - centre)))
                outliers = []
                if len(got) >= min_siblings:
                    for imu, r, e in got:
                        z = (e.x - centre) / math.hypot(spread, e.sigma)
                        if abs(z) > z_limit:
                            outliers.append(Outlier(imu, model, axis, param, math.exp(e.x),
                                                    math.exp(centre), z, r['key']))
                out.append(Spread(model, axis, param, len(got), math.exp(centre),
                                  math.expm1(spread), tuple(outliers)))
    return out


class Change(NamedTuple):
    """A night on which an IMU's parameter moved beyond what the intervals allow."""

    imu_id: str
    axis: str
    param: str
    start_ns: int
    path: str
    ratio: float
    z: float
    n_reference: int


def changes(rows: list[dict], params=VIEW_PARAMS, z_limit: float = CHANGE_Z,
            min_change: float = MIN_CHANGE) -> list[Change]:
    """
    Return every night that moved from its IMU's reference (see the module doc).

    Parameters
    ----------
    rows : list of dict
        Store rows.
    params : sequence of str
        Parameters to test.
    z_limit : float
        Threshold on z.
    min_change : float
        Smallest relative change reported.

    Returns
    -------
    list of Change
        In IMU, axis, parameter and time order.

    """
    out = []
    for imu, imu_rows in by_imu(rows).items():
        for axis in AXES:
            nights = [r for r in imu_rows if r['axis'] == axis]
            for param in params:
                w_sum = wx_sum = 0.0
                n_ref = 0
                for r in nights:
                    e = estimate(r, param)
                    if e is None:
                        continue
                    if n_ref:
                        ref, ref_var = wx_sum / w_sum, 1.0 / w_sum
                        z = (e.x - ref) / math.sqrt(e.sigma ** 2 + ref_var)
                        ratio = math.exp(e.x - ref)
                        if abs(z) > z_limit and abs(ratio - 1.0) >= min_change:
                            out.append(Change(imu, axis, param, int(r['start_ns']), r['path'],
                                              ratio, z, n_ref))
                            continue   # a moved night does not join the reference
                    w = 1.0 / e.sigma ** 2
                    w_sum, wx_sum, n_ref = w_sum + w, wx_sum + w * e.x, n_ref + 1
    return out
