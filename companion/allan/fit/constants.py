"""The fit's numerical rules, each with the reason for its value."""

from __future__ import annotations

from companion.allan.terms import LINEAR_EFFECTS

#: effects with a nonlinear shape parameter (tau_c, freq_hz) beside their linear magnitude
NONLINEAR_EFFECTS = ("gauss_markov", "sinusoid")
#: the linear parameter of each nonlinear effect (its square is the design column's coefficient)
NL_LINEAR = {"gauss_markov": "sigma", "sinusoid": "amplitude"}
#: the shape parameter of each nonlinear effect (found by a grid and a bounded 1-D search)
NL_SHAPE = {"gauss_markov": "tau_c", "sinusoid": "freq_hz"}
#: the order of the terms in a model: the covariance's pair sums are remembered per ordered set of term shapes
ORDER = {x: i for i, x in enumerate(LINEAR_EFFECTS + NONLINEAR_EFFECTS)}

#: quantization, ramp, gauss_markov and sinusoid enter only if they lower the BIC by more than this
#: ("very strong" evidence on the scale of Kass & Raftery 1995: 2 ln(Bayes factor) > 10); with ~18 strongly
#: correlated points, plain BIC lets a ramp stand in for a random walk in about one record out of five
EXTRA_BIC_MARGIN = 10.0
#: what effects=None tries; a sinusoid is fitted only when asked for (on octave-spaced points its
#: oscillating AVAR fits chance bumps too easily)
AUTO_EFFECTS = LINEAR_EFFECTS + ("gauss_markov",)
#: a Gauss-Markov correlation time shorter than this many sample periods is a filter's or the sampling's shape
GM_MIN_SAMPLES = 3.0
#: grid points of a shape parameter's search: a Gauss-Markov AVAR is one smooth hump, a sinusoid's oscillates
SHAPE_GRID = {"gauss_markov": 25, "sinusoid": 61}
#: a shape optimum within this fraction of the grid's span from either end is pinned there: not identified
SHAPE_EDGE = 0.02

#: quantization is a candidate only where the data show its slope: AVAR between the two smallest cluster times
#: falls at least as fast as tau^QUANT_SLOPE (quantization alone: tau^-2; white noise: tau^-1, less under a
#: filter). Without that region a quantization term only stands in for something else at short tau (an output
#: line near the Nyquist frequency, a filter's bump) and moves N.
QUANT_SLOPE = -1.5
#: ... and, where there is a third, between the second and third at least as fast as tau^QUANT_SLOPE2: a
#: quantization term that passes the first test is at least 1.41x the white noise at the smallest cluster time,
#: so the next octave still falls like tau^-1.34 or faster, where white noise alone falls like tau^-1. An output
#: line near the Nyquist frequency lifts the smallest cluster time alone (point samples alternate, pairs
#: average it out) and passes the first test but not this one
#: (tests/allan/test_fit.py::test_quantization_only_where_its_slope_is).
QUANT_SLOPE2 = -1.2

#: the log's low-pass cut-off stands unless it lies outside the data's profile interval at this level
FILTER_LOG_LEVEL = 0.99
#: relative uncertainty of a modelled low-pass filter's shape, per unit of its bend 1 - AVAR tau / N^2: a real
#: filter chain is no exact 2-pole Butterworth at exactly f_c
FILTER_SHAPE_ERROR = 0.25
#: uncertainty of the bias-instability (flicker) AVAR at the first cluster times, in units of the excess a
#: sampled flicker without anti-alias filter has over the plateau
#: (:func:`companion.allan.confidence.flicker_sampling_excess`: +19 % at tau0, +9 % at 2 tau0, +3 % at 4 tau0);
#: fully correlated over tau (one unknown shape)
FLICKER_SHAPE_ERROR = 1.0
#: the data's roll-off: the filter orders profiled, and the lowest cut-off of each in units of 1 / tau_max (a
#: 2-pole at 30 / tau_max and a 1-pole at 8 / tau_max lower the AVAR at the longest cluster time by 0.5 % and 3 %)
FILTER_ORDERS = {2: 30.0, 1: 8.0}
#: a 2-pole filter above this many times the sample rate bends no cluster time: the top of its cut-off grid
TWO_POLE_MAX = 3.0
#: a first-order roll-off is looked for only below this fraction of the sample rate: above it a first-order and
#: a 2-pole roll-off differ at the first two or three octave points only, where how the samples were taken
#: (point or averaged, a digital filter, a sensor's averaging window) shapes the curve as much as the order, and
#: FILTER_SHAPE_ERROR carries that (1-pole readings of 29-53 Hz roll-offs of real sensors moved N by up to 5 %
#: and out of its interval)
FIRST_ORDER_MAX = 0.1
#: cut-off grid points per order: the 2-pole range spans more octaves than the first-order one
CUTOFF_GRID = {2: 41, 1: 21}
#: the grid points of a shape parameter's profile over which a correlated linear parameter's interval is taken
PROFILE_POINTS = 13

#: the misfit rule: a model error is added when chi^2 exceeds dof by more than this many of chi^2's standard
#: deviations sqrt(2 dof) (a consistent model passes it with probability ~0.998)
MISFIT_SIGMAS = 3.0
#: the relative model error is searched between these (log-bisection): below 1e-4 it changes no weight, and 3
#: (300 % of the AVAR) already leaves the points to their Allan-variance correlations alone
MODEL_ERROR_RANGE = (1e-4, 3.0)
#: bisection steps of the model-error search: the log range is halved to 1e-11 of itself
MODEL_ERROR_STEPS = 40
#: the EDF of a point when the caller gives none: a first weight only, the full covariance follows
DEFAULT_EDF = 10.0

#: The interval of a linear term is found by test inversion unless the pivot's nu at the estimate is at least
#: this (relative sd <= 1.4 %): the covariance then hardly changes over the interval and the pivot is the same
#: interval (N of hours at tens of Hz, nu ~ 1e5-1e6), at a tenth of the cost.
INVERT_MAX_NU = 1e4

#: A long-tau term (bias instability, rate random walk) is "resolved" only when the record shows it: it must
#: dominate the fitted AVAR (at least half of it) from a cluster time tau_d no longer than a tenth of the
#: record, where a single-segment Allan variance still has an EDF of about 5 or more (rate random walk: EDF
#: ~ N/m at tau = T/10), so that the octaves tau_d .. T/2 carry it. A record therefore needs to be at least
#: RESOLVE_RECORD_FACTOR x tau_d long, tau_d being the shortest tau from which the term dominates (a factor of
#: twenty is too strict: K of a 2000 s record with tau_d = 173 s is recovered within its interval,
#: tests/estimators/test_online.py).
RESOLVE_RECORD_FACTOR = 10.0
#: the terms the record rule applies to: those seen only at long cluster times
RESOLVE_EFFECTS = ("bias_instability", "random_walk")
#: ... and never from less than a minute of record: the rule above is scale-free, so a short record whose
#: AVAR rises early (half a minute of a copter at rest, a 0.29 s batch-sampler burst) would "resolve" a rate
#: random walk or a bias instability from cluster times of a second or of milliseconds, where a drift, a slow
#: filter or temperature look the same; below 60 s the analysis deems even N unusable
#: (analysis.sufficiency.FIT_MIN_SECONDS).
RESOLVE_MIN_RECORD_S = 60.0

#: one-sided 95 % normal quantile of an upper bound
Z95_ONE_SIDED = 1.6448536269514722
