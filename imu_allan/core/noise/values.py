"""
The values of a noise model: one axis (AxisNoise) and a whole IMU (NoiseSpec).

Every value is in SI units of the axis' samples (``unit`` = rad/s for a gyro,
m/s^2 for an accelerometer).  B follows the paper's convention (Maia et al. eq. 8):
B is the bias instability read off the Allan deviation floor, ADEV_min = 0.664 B
for flicker noise, and for a first-order Gauss-Markov term with correlation time T
the driving PSD is S_B = 2 B^2 ln2 / (pi 0.4365^2 T), which puts the Gauss-Markov
ADEV peak (0.4365 sqrt(S_B T) at tau = 1.89 T) on the same floor 0.664 B.

Which term of :data:`imu_allan.core.noise.terms.TERMS` each field holds is written
in that registry (each entry's ``read`` and ``write``); a term without a field of its
own lives in :attr:`AxisNoise.extra`.
"""

from dataclasses import dataclass, field
import math
from typing import NamedTuple

#: 0.4365: peak of the Gauss-Markov ADEV in units of q sqrt(T) (IEEE Std 952 C.1).
GM_PEAK_FACTOR = 0.4365
#: 0.664 = sqrt(2 ln2 / pi): flicker ADEV floor per unit of B (IEEE Std 952 C.1).
FLICKER_FLOOR = math.sqrt(2.0 * math.log(2.0) / math.pi)


@dataclass(frozen=True)
class GaussMarkov:
    """
    A first-order Gauss-Markov term.

    Attributes
    ----------
    B : float
        Bias-instability level [unit] (paper convention, see module docstring).
    T : float
        Correlation time [s].

    """

    B: float
    T: float

    @property
    def psd(self) -> float:
        """Driving white-noise PSD S_B [unit^2/s] (paper eq. 8)."""
        return 2.0 * self.B ** 2 * math.log(2.0) / (math.pi * GM_PEAK_FACTOR ** 2 * self.T)

    @property
    def q(self) -> float:
        """Driving noise density q = sqrt(S_B) [unit/s^0.5]."""
        return math.sqrt(self.psd)

    @property
    def sigma(self) -> float:
        """Stationary standard deviation sqrt(S_B T / 2) [unit]."""
        return math.sqrt(self.psd * self.T / 2.0)

    @classmethod
    def from_psd(cls, psd: float, T: float) -> 'GaussMarkov':
        """Build from the driving PSD q^2 [unit^2/s] and correlation time T [s]."""
        return cls(B=math.sqrt(psd * math.pi * GM_PEAK_FACTOR ** 2 * T / (2.0 * math.log(2.0))),
                   T=T)


@dataclass(frozen=True)
class Sinusoid:
    """
    A sinusoidal error A sin(2 pi f0 t + phase).

    Attributes
    ----------
    A : float
        Amplitude [unit].
    f0_hz : float
        Frequency [Hz].

    """

    A: float
    f0_hz: float


class TermValue(NamedTuple):
    """
    One instance of a registry term that has no field of its own in :class:`AxisNoise`.

    Attributes
    ----------
    term : str
        Its name in :data:`imu_allan.core.noise.terms.TERMS`.
    values : tuple of float
        Its parameters in the order of the term's ``symbols``, SI.

    """

    term: str
    values: tuple


@dataclass(frozen=True)
class AxisNoise:
    """
    Stochastic error model of one axis; a term set to 0 (or None) is absent.

    Attributes
    ----------
    N : float
        White noise density (angle / velocity random walk) [unit*s^0.5].
    B : float
        Bias instability [unit]: a Gauss-Markov term with ``T_B`` when T_B is set
        (the paper's model), otherwise flicker (1/f) noise.
    T_B : float or None
        Correlation time of the bias-instability Gauss-Markov term [s].
    K : float
        Rate random walk [unit/s^0.5].
    Q : float
        Quantization noise [unit*s] (AVAR 3 Q^2 / tau^2).
    R : float
        Rate ramp [unit/s] (AVAR R^2 tau^2 / 2).
    gauss_markov : tuple of GaussMarkov
        Further Gauss-Markov terms.
    sinusoids : tuple of Sinusoid
        Sinusoidal errors.
    bias : float
        Constant offset [unit], e.g. 9.80665 on an upward accelerometer axis.
    extra : tuple of TermValue
        Registry terms without a field of their own (a newly added term).

    """

    N: float = 0.0
    B: float = 0.0
    T_B: float | None = None
    K: float = 0.0
    Q: float = 0.0
    R: float = 0.0
    gauss_markov: tuple[GaussMarkov, ...] = field(default_factory=tuple)
    sinusoids: tuple[Sinusoid, ...] = field(default_factory=tuple)
    bias: float = 0.0
    extra: tuple[TermValue, ...] = field(default_factory=tuple)

    def all_gauss_markov(self) -> tuple[GaussMarkov, ...]:
        """Every Gauss-Markov term: the bias-instability one (if T_B is set) first."""
        head = (GaussMarkov(self.B, self.T_B),) if self.B > 0 and self.T_B else ()
        return head + tuple(self.gauss_markov)

    @property
    def has_flicker(self) -> bool:
        """Return True when B is modelled as flicker (1/f) noise, i.e. T_B is not set."""
        return self.B > 0 and not self.T_B


@dataclass(frozen=True)
class NoiseSpec:
    """
    Noise model of a whole six-axis IMU.

    Attributes
    ----------
    name : str
        Free-text name of the IMU ('' when not given).
    axes : dict of str to AxisNoise
        One entry per name in ``imu_allan.AXES`` (absent axes are ``AxisNoise()``).

    """

    name: str
    axes: dict[str, AxisNoise]
