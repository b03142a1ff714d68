"""Names in a user's words: every term has a noun, and notes lose the internal labels."""

import pytest

from imu_allan.core.noise.terms import TERMS
from imu_allan.core.noise.words import speak, spoken


def test_every_term_has_a_noun_of_plain_words():
    for name, term in TERMS.items():
        assert term.noun and '_' not in term.noun, name


@pytest.mark.parametrize('name, words', [
    ('N', 'N'), ('T_B', 'T_B'), ('T_f', 'filter time constant'),
    ('gauss_markov.B', 'extra Gauss-Markov B'), ('gauss_markov_2.T', 'extra Gauss-Markov 2 T'),
    ('sinusoid.A', 'sinusoid amplitude'), ('sinusoid_2.f0_hz', 'sinusoid 2 frequency'),
    ('rate_ramp', 'rate ramp'), ('kalman_qr.yaml', 'kalman_qr.yaml'), ('b_gm', 'b_gm'),
])
def test_spoken_names(name, words):
    assert spoken(name) == words


def test_a_note_keeps_its_figures_and_file_names_and_loses_the_labels():
    note = ('B, T_B: the bias instability (B 0.00412, T_B 0.105 s) and gauss_markov (B 0.00385, '
            'T 10 s) have levels the data do not order; see kalman_qr.yaml b_gm; '
            'gauss_markov_2.T and T_f, rate_ramp')
    said = speak(note)
    assert said == ('B, T_B: the bias instability (B 0.00412, T_B 0.105 s) and extra '
                    'Gauss-Markov (B 0.00385, T 10 s) have levels the data do not order; see '
                    'kalman_qr.yaml b_gm; extra Gauss-Markov 2 T and filter time constant, '
                    'rate ramp')
