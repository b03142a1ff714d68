"""
Every threshold the fit and the effect search decide by, each with its reason, once.

The fit (:mod:`imu_allan.core.fit`) and the search (:mod:`imu_allan.core.search`) read
these and define none of their own; numerical tolerances of the solvers (step sizes,
iteration limits) are not decisions and stay with their solvers.
"""

# ---------------------------------------------------------------- is the model enough

#: A model whose GLS chi-square p-value is at least this explains its curve: the search
#: adds nothing, the fit is consistent, and its profile intervals are plain
#: likelihood-ratio intervals.  Below it the model is rejected.
P_CONSISTENT = 1e-3
#: ... or one inside the curve's 95 % band (or within 5 %) at this share of the taus
#: (a long curve's chi-square rejects a good model on tiny covariance errors).
FOLLOW_SHARE = 0.85

# ------------------------------------------------------------ what a term must buy

#: Penalty per parameter for keeping a term of the base model (AIC): a term the paper's
#: model holds stays when it lowers the chi-square by more than 2 per parameter.
KEEP_PENALTY = 2.0
#: Drop of the criterion, beyond BIC's ln(k) per parameter, that an effect must buy to
#: be named (bench/search_power.py: no false effect on 78 clean axes); models within it
#: of the chosen one on the same criterion are rivals that fit about as well.
DELTA_MIN = 10.0
#: A nonlinear parameter within this factor of an end of its search range is not
#: identified by the taus: the fit reshaping the curve, not a measurement.
PIN_MARGIN = 1.02
#: The shortest taus must fall at least this steeply (ADEV slope) for quantization to
#: be a candidate (quantization alone falls as -1).
QUANTIZATION_SLOPE = -0.75
#: A filter time constant below this share of the shortest fitted tau is not identified.
FILTER_MIN_TAU_SHARE = 0.2

# --------------------------------------------------------------------- the search

#: Most effects the search adds per axis.
MAX_STEPS = 4
#: Rival effects re-fitted (IRLS) and compared by their full likelihood at each step.
N_RIVALS = 3
#: A rival structure (the runner-up effect of a step in its place) within this many
#: units of -2 ln L + BIC of the chosen model fits about equally well: the margin an
#: effect must buy (:data:`DELTA_MIN`).
RIVAL_DELTA = DELTA_MIN
#: Grid points over the range of T_B (log-spaced) when its profile is searched for rival
#: minima.
GRID_POINTS = 8
#: A likelihood ratio (or chi-square drop) at least this large, yet short of what naming
#: an effect needs, is "cannot tell from this record" rather than "not supported".
CANNOT_TELL_LR = 4.0

# -------------------------------------------------------------- time-domain evidence

#: A sinusoid's amplitude from the curve and from the periodogram agree within this.
AMPLITUDE_FACTOR = 3.0
#: False-alarm probability of a periodogram line over the band searched.
LINE_FALSE_ALARM = 1e-3
#: Blocks the record is cut into for the ramp test (the covariance is blocks^2).
RAMP_BLOCKS = 256
#: Likelihood-ratio statistic a ramp must exceed: chi2(1) at about 1e-5, since the
#: search asks this of every axis (few false ramps over a fleet of axes).
RAMP_LR_MIN = 19.5

# ------------------------------------------------------------- the thermal coefficient

#: The temperature changed when its block means span at least this [degC]: below it
#: (a temperature sensor's quantization step) no thermal coefficient is read.
THERMAL_MIN_SPAN_C = 0.01
#: Blocks the record is cut into for the thermal regression (core/search/thermal.py):
#: the temperature's block means must follow its changes (a 40-minute cycle in a
#: 2.8 h record is 20 blocks per cycle), and the covariance is blocks^2.
THERMAL_BLOCKS = 512

# ------------------------------------------------- a slow drift, without a temperature

#: Blocks the record is cut into for the drift test (core/search/drift.py), as for the
#: thermal regression: a 40-minute cycle in a 2.8 h record is 20 blocks per cycle.
DRIFT_BLOCKS = 512
#: Cosines of the block means' differences taken as the smooth part (a drift), one test
#: each: 4 (up to 1.5 cycles over the record: a warming, a ramp to a level) and 12 (up
#: to 5.5: a 40-minute cycle in a 2.8 h record is 4.2); fewer cosines leave more of a
#: random walk outside them, so a warming is found sooner with 4.
DRIFT_SMOOTH = (4, 12)
#: Bootstrap draws of the statistic's null distribution: p-values to 1/400, four draws
#: at least below DRIFT_ALPHA.
DRIFT_SIMS = 400
#: A random walk is named a drift when its combined p-value (the smooth part holds more
#: random walk than the rest allows) is below this: the analysis asks it of every axis
#: whose K is an estimate, and a false alarm turns a true K into a bound
#: (bench/drift_power.py: false alarms 4 of 900 simulated random walks at 10-400 Hz; the
#: clean ADIS16405 and MPU-6050 axes' p-values are 0.05 or more).
DRIFT_ALPHA = 0.01

# ------------------------------------------------------------------ what is reported

#: The lowest ADEV (a datasheet's in-run bias stability) is reported only where the
#: curve measures it: an interior minimum (the curve rises after it) whose 95 % interval
#: spans at most this factor (hi / lo; about 17 equivalent degrees of freedom).  Read
#: at the last taus, where a 3 h record's floor interval spans 70x, it told nothing.
FLOOR_SPREAD_MAX = 2.0

# ------------------------------------------------------------ settling after power-on

#: A transient at the start of a record (:mod:`imu_allan.core.allan.settling`) counts
#: when its amplitude is this many times the record's own wander at its time constant
#: (bench/settle_power.py): settled noise reached 10.3 in 180 simulated windows (white,
#: Gauss-Markov, random walk at 10-400 Hz) and 8.4 in the six ADIS16405 runs; the
#: MPU-6050 record's accel_y settles by 0.7 mg in its first minutes, 24.7 wanders, too
#: little to tell in 11 min.  A transient of 60 Allan deviations is found.
SETTLE_SCORE = 30.0
#: The output has settled where what is left of the transient is this many wanders
#: (about the bias instability: it then adds little to the Allan variance).
SETTLE_LEFT = 1.0
#: A second, slower time constant (at least 3 times the first) sets the cut when its
#: amplitude is this many wanders: noise alone fits a slow part of about one (a
#: transient of two time constants, or a ramp to a level, has a slower tail than the
#: one exponential that fits it best).
SETTLE_TAIL = 5.0
#: Passes of the settling search: after a cut, what follows is judged again.
SETTLE_PASSES = 3

#: A plan's time longer than this many times the record it came from is a lower limit:
#: the fitted model has only seen taus up to a fraction of the record, and a term that
#: surfaces at longer taus (B flattening, K rising) adds width, so the true time is longer
#: (the ADIS16405's 2-min plan said K in 22 min, its 2.78 h record 17 h).
LOWER_LIMIT_RATIO = 3.0

# --------------------------------------------------------- zero-filled fields (input)

#: Exact zeros on an axis before they can be fills of incomplete packets (a few exact
#: zeros of a fine-grained axis are chance; pipeline/zeros.py).
ZERO_MIN = 10
#: Exact zeros this many times as frequent as the axis' nearest non-zero value are a
#: pile, not a level of the distribution: a quantised axis reads 0 about as often as
#: the levels next to it (MPU-6050 gyro_y: 1,877 zeros, about as many at +-1 LSB).
ZERO_RATIO = 4.0
#: Those nearest values count only within this many sds of the axis' non-zero values
#: from 0; beyond, the axis is quantised coarser than its noise (0 may hold most
#: samples) or 0 lies outside its values.
ZERO_STEP_MAX = 0.5
#: ... or within this many LSBs (the least step between distinct values): 0 is then a
#: level of a grid coarser than the noise (a gyro of 4 sds per LSB reads 0 a sixth of
#: the time at a bias of 3 sds), not a value off the axis' others.
ZERO_GRID = 1.5
#: With no value near 0, zeros are fills when 0 lies this many sds from the mean of the
#: axis' other values: a Gaussian axis reads 0 there once in about 1e9 samples.
ZERO_FAR = 6.0

# ------------------------------------------------- messages lost on irregular stamps

#: Messages are counted in windows of this length [s] on irregular (host) stamps: long
#: against a host's read bursts (tens of ms), short enough for 60 windows in 10 min.
LOST_WINDOW_S = 10.0
#: Windows counted before the spread of the counts is judged.
LOST_MIN_WINDOWS = 20
#: The counts' variance over their mean (Fano factor) beyond which messages were lost:
#: a sensor read at its own rate gives counts that differ by a read burst at most (the
#: MPU-6050 record: 0.028), messages lost one by one at random with probability p add
#: p (10 %: 0.142), in runs many times p (2 % in runs of 20: 0.79).
LOST_FANO = 0.06

# ------------------------------------------------- values interpolated between updates

#: Triples judged on a straight line where twice their area over (t, y) is at most this
#: share of their values' sum times their span: float32 interpolation keeps 1e-7, a
#: sensor's noise puts 0-0.05 of its triples there (pipeline.interpolated).
INTERP_REL_TOL = 1e-6
#: Moving triples counted before an axis is judged.
INTERP_MIN_TRIPLES = 2000
#: The share of moving triples on a line that makes an axis interpolated: 0.2 at 2.5
#: messages per update, 0-0.05 on the bench's own records (docs/input_gate.md).
INTERP_MIN = 0.1

# ------------------------------------------------- values on a coarse grid

#: A grid (the least step between distinct values: an LSB, the digits of a CSV) is named
#: where rounding to it raises N by this share or more: 1 %, beside the 1-3 % half-width
#: of N's interval on an hour's record (an ADIS16405's 3.3 mg accelerometer LSB, about
#: one sd of a sample, raises N 4-6 %).
ROUNDING_N_RAISE = 0.01
#: A grid step this many sds of one sample or more leaves the white noise unresolved:
#: rounding is no additive noise once the sd is below half a step (Widrow and Kollar,
#: Quantization Noise, 2008), and a simulated axis rounded to 8 sds read N at 0.49x.
ROUNDING_RATIO_MAX = 2.0

# ---------------------------------------------------------- a noise level that changed

#: The AVAR at a white-noise tau differs between the record's stretches when Cochran's
#: Q test gives a p-value below this (core/allan/stretches.py): one false widening in a
#: thousand axes of a steady sensor; the ADIS16405 accelerometers' hours give p < 1e-7.
LEVEL_P = 1e-3
