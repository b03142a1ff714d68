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
