"""
Parameter and term names in a user's words, for text people read.

The fit, the plan and result.json name parameters by term label and symbol
(``gauss_markov_2.T``, ``sinusoid.f0_hz``, ``T_f``): stable keys programs parse.
Summaries, plan lines and notes show them through :func:`spoken` and :func:`speak`
(``extra Gauss-Markov 2 T``, ``sinusoid frequency``, ``filter time constant``), with
each term's noun taken from the registry (``Term.noun``).
"""

import re

from imu_allan.core.noise.terms import base_name, TERMS

#: Symbols whose letter says little to a user; the others (N, B, K, T_B, T, Q, R) are
#: the ones datasheets and IEEE Std 952 use.
SYMBOL_WORDS = {'T_f': 'filter time constant', 'A': 'amplitude', 'f0_hz': 'frequency'}

#: A term label with its symbol (``sinusoid_2.f0_hz``), a bare label with an underscore
#: (``rate_ramp``), or ``T_f``.
_TOKEN = re.compile(r'\b(?:[a-z]+(?:_[a-z0-9]+)*\.[A-Za-z][A-Za-z0-9_]*|'
                    r'[a-z]+(?:_[a-z0-9]+)+|T_f)\b')


def _noun(label: str) -> str | None:
    """Return a term label's noun ('gauss_markov_2' -> 'extra Gauss-Markov 2'), or None."""
    try:
        base = base_name(label)
    except KeyError:
        return None
    number = label[len(base) + 1:]
    return (TERMS[base].noun or base) + (f' {number}' if number else '')


def spoken(name: str) -> str:
    """
    Return a reported parameter name in a user's words.

    Parameters
    ----------
    name : str
        A plan or fit name: a plain symbol ('N', 'T_f'), or '<label>.<symbol>'
        ('gauss_markov.B', 'sinusoid_2.f0_hz'), or a term label ('rate_ramp').

    Returns
    -------
    str
        'N', 'filter time constant', 'extra Gauss-Markov B', 'sinusoid 2 frequency',
        'rate ramp'; a name it does not know is returned unchanged.

    """
    label, dot, symbol = name.partition('.')
    if dot:
        noun = _noun(label)
        return name if noun is None else f'{noun} {SYMBOL_WORDS.get(symbol, symbol)}'
    if name in SYMBOL_WORDS:
        return SYMBOL_WORDS[name]
    noun = _noun(name) if '_' in name else None
    return name if noun is None else noun


def speak(text: str) -> str:
    """Return a note with every parameter and term name in it :func:`spoken`."""
    return _TOKEN.sub(lambda m: spoken(m.group(0)), text)


__all__ = ['SYMBOL_WORDS', 'speak', 'spoken']
