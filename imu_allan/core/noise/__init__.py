"""
The noise model: its terms, parameter files, quoted units and simulation.

:mod:`.model` (the terms and their closed-form Allan variance), :mod:`.params` (parameter
files: AxisNoise, NoiseSpec), :mod:`.units` (deg/h, ug/rtHz ...), :mod:`.simulate`
(Farrell's state-space generator and the effect generators).
"""
