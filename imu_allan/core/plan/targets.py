"""
Precision targets as people type them: ``N=0.1``, ``K=25%``, ``"N=5%,B=0.1"``.

Numpy-free, so the command line and the node's parameter check read targets without
loading the planner.
"""

from imu_allan.errors import InputError


def parse_targets(items) -> dict:
    """
    Return {parameter: relative 95 % half-width} from ``P=W`` items.

    Parameters
    ----------
    items : str or iterable of str
        Items such as 'N=0.1', 'K=25%' or 'K=none' (no target: never waited for); a
        string may hold several, separated by commas or spaces ('' gives no targets).

    Returns
    -------
    dict of str to float
        Relative half-widths [-] (inf: no target).

    Raises
    ------
    InputError
        An item without '=', or a width outside (0, 10).

    """
    if isinstance(items, str):
        items = items.replace(',', ' ').split()
    out = {}
    for item in items or []:
        name, sep, text = str(item).partition('=')
        text = text.strip().lower()
        try:
            value = (float('inf') if text in ('none', 'off') else
                     float(text.rstrip('%')) / 100.0 if text.endswith('%') else float(text))
        except ValueError:
            value = float('nan')
        if not sep or not name.strip() or not (0.0 < value < 10.0 or value == float('inf')):
            raise InputError(f'target {item!r}: expected PARAM=WIDTH with a relative '
                             'half-width such as N=0.1 or K=25%')
        out[name.strip()] = value
    return out


#: No target: the parameter is reported but never waited for.
NO_TARGET = float('inf')
#: Target profiles by use: relative 95 % half-widths of N, B, T_B, K and of every other
#: term ('*').  A visual-inertial estimator (Kalibr's imu.yaml, VINS, OpenVINS) takes
#: the white noise and the random walk only, and its tuning inflates both by a factor
#: anyway, so K within +-50 % does (K is the slowest term: +-50 % needs a quarter of the
#: record +-25 % needs); an EKF with a bias state (robot_localization, a Gauss-Markov
#: bias) uses B as well; 'full' characterises every term (datasheet work).
PROFILES = {
    'full': {'N': 0.10, 'B': 0.10, 'T_B': 0.25, 'K': 0.25, '*': 0.25},
    'ekf': {'N': 0.10, 'B': 0.25, 'T_B': NO_TARGET, 'K': 0.25, '*': NO_TARGET},
    'vio': {'N': 0.10, 'B': NO_TARGET, 'T_B': NO_TARGET, 'K': 0.50, '*': NO_TARGET},
}
PROFILES['kalibr'] = PROFILES['vio']
#: The profile used when none is given: every term, as before profiles existed (a
#: characterisation reports all; a filter's user names the filter).
DEFAULT_PROFILE = 'full'


def profile_targets(profile: str | None, items=None) -> dict:
    """
    Return the targets of a profile, with explicit ``P=W`` items overriding it.

    Parameters
    ----------
    profile : str or None
        A key of :data:`PROFILES` (None or '': :data:`DEFAULT_PROFILE`).
    items : str or iterable of str, optional
        Explicit targets (:func:`parse_targets`).

    Returns
    -------
    dict of str to float
        Relative half-widths [-] of N, B, T_B, K and '*' (every other term).

    Raises
    ------
    InputError
        An unknown profile or a malformed target.

    """
    name = profile or DEFAULT_PROFILE
    if name not in PROFILES:
        raise InputError(f'unknown target profile {name!r}: expected one of '
                         f'{", ".join(PROFILES)}')
    return dict(PROFILES[name], **parse_targets(items))


def targeted(targets: dict) -> list:
    """Return the names of the parameters with a target ('*' reads 'other terms')."""
    return [{'*': 'other terms'}.get(k, k) for k, v in targets.items() if v != NO_TARGET]
