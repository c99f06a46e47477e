"""The backward step for added effects (companion.gap.workflow._drop_unneeded): an effect a later step made
unnecessary is dropped at the level it passed when added; an effect the data need is kept."""

import numpy as np

from companion.gap.candidates import fit_terms
from companion.gap.compare import measure
from companion.gap.backward import drop_unneeded as _drop_unneeded
from companion.sim.synth import synthesize_axis

RATE = 50.0
WHITE = {"effect": "white_noise", "N": 1e-3}


def _state(truth, state_terms, seed=4, n=40_000):
    y = synthesize_axis(truth, RATE, n, np.random.default_rng(seed))
    meas = measure(y, RATE)
    return y, meas, fit_terms(meas, state_terms, fixed=[0], intervals=False)


def test_a_leftover_sinusoid_beside_the_line_is_dropped_and_the_line_kept():
    """A line of 4e-3 rad/s at 1.6 Hz in white noise, and 3e-4 at 1.3 Hz, far below its level; the state
    carries both (what a first sinusoid fitted off the line's frequency leaves once the periodogram's line
    is added: fitted 1.3e-3 here): the leftover is dropped with a note, the line stays (amplitude within
    10 %, frequency within 0.05 Hz after its shape is re-optimised), whichever way the two are ordered."""
    line = {"effect": "sinusoid", "amplitude": 4e-3, "freq_hz": 1.6}
    weak = {"effect": "sinusoid", "amplitude": 3e-4, "freq_hz": 1.3}
    for order in ([line, weak], [weak, line]):
        y, meas, base = _state([WHITE, line, weak], [WHITE] + [dict(t) for t in order], seed=6)
        assert min(t["amplitude"] for t in base.terms[1:]) > 1e-3 * 0.5
        terms, held, _, notes = _drop_unneeded(meas, base, {0}, 1, {}, y, RATE)
        assert [t["effect"] for t in terms] == ["white_noise", "sinusoid"] and held == {0}
        assert abs(terms[1]["freq_hz"] - 1.6) < 0.05 and abs(terms[1]["amplitude"] / 4e-3 - 1) < 0.1
        assert len(notes) == 1 and "no longer needed" in notes[0] and "freq_hz 1.3" in notes[0]


def test_effects_the_data_need_are_kept():
    """Two lines (1.6 Hz and 0.2 Hz) and a rate random walk, each 3x or more above the white noise at its
    own cluster times: nothing is dropped, and an index-keyed alternative stays with its term."""
    truth = [WHITE, {"effect": "sinusoid", "amplitude": 4e-3, "freq_hz": 1.6},
             {"effect": "sinusoid", "amplitude": 2e-3, "freq_hz": 0.2}, {"effect": "random_walk", "K": 3e-4}]
    y, meas, base = _state(truth, [dict(t) for t in truth])
    terms, held, alts, notes = _drop_unneeded(meas, base, {0}, 1, {3: "alt"}, y, RATE)
    assert [t["effect"] for t in terms] == ["white_noise", "sinusoid", "sinusoid", "random_walk"]
    assert notes == [] and alts == {3: "alt"}


def test_a_fitted_filter_that_stood_for_a_short_gauss_markov_term_is_weighed_again():
    """Truth: white + flicker + random walk + a Gauss-Markov term (sigma 1.69e-3, tau_c 0.248 s, 12 samples)
    + a 1.41 Hz line, 2 h at 50 Hz (a fresh hard-tier draw of bench_gap). With the line not yet named the
    Gauss-Markov fit was pulled to 3 samples and the filter rule took a 1 Hz filter; the workflow ended at
    filter + line + quantization. Weighed again in that final state the Gauss-Markov term wins, the
    quantization is dropped, and the term's parameters are within 30 % of the truth."""
    from companion.gap.spectral import significant_lines
    from companion.gap.backward import filter_or_gauss_markov as _filter_or_gauss_markov

    gm = {"effect": "gauss_markov", "sigma": 1.6862665e-3, "tau_c": 0.24761158}
    line = {"effect": "sinusoid", "amplitude": 3.5883434e-3, "freq_hz": 1.4136387}
    model = [{"effect": "white_noise", "N": 4.5012394e-4}, {"effect": "bias_instability", "B": 6.177901e-05},
             {"effect": "random_walk", "K": 2.4658729e-06}]
    truth = [{"effect": "white_noise", "N": 3.3657123e-4}, {"effect": "bias_instability", "B": 5.8736384e-05},
             {"effect": "random_walk", "K": 2.0935693e-06}, gm, line]
    y = synthesize_axis(truth, RATE, 360_000, np.random.default_rng(847516820605003))
    meas = measure(y, RATE)
    meas.lines = significant_lines(y, RATE)
    ended = [{"effect": "white_noise", "N": 1.1826e-3, "cutoff_hz": 1.0, "order": 1}, dict(model[1]), dict(model[2]),
             {"effect": "sinusoid", "amplitude": 3.5648e-3, "freq_hz": 1.42793}, {"effect": "quantization", "Q": 3.62e-5}]
    base = fit_terms(meas, ended, [1, 2], intervals=False)
    out = _filter_or_gauss_markov(meas, base, {1, 2}, model, (None, 2, False), y, RATE, {}, None)
    assert out is not None
    terms, held, _, note = out
    assert [t["effect"] for t in terms[3:]] == ["sinusoid", "gauss_markov"]
    assert not terms[0].get("cutoff_hz") and held == {1, 2}
    assert abs(terms[4]["sigma"] / gm["sigma"] - 1) < 0.3 and abs(terms[4]["tau_c"] / gm["tau_c"] - 1) < 0.3
    assert "weighed again" in note and "quantization" in note


def test_a_filter_the_data_show_is_kept():
    """White noise through a 5 Hz two-pole filter at 50 Hz (no other effect): the final state's filter is
    weighed again and kept (a Gauss-Markov term that short is the filter's look-alike; the filter rule keeps
    the one-parameter filter)."""
    from companion.gap.backward import filter_or_gauss_markov as _filter_or_gauss_markov

    from companion.gap.lowpass_check import synthesize_filtered_white

    white = {"effect": "white_noise", "N": 1e-3, "cutoff_hz": 5.0, "order": 2}
    y = synthesize_filtered_white(1e-3, 5.0, RATE, 100_000, np.random.default_rng(3))
    meas = measure(y, RATE)
    model = [{"effect": "white_noise", "N": 1e-3}]
    base = fit_terms(meas, [dict(white)], [], intervals=False)
    assert _filter_or_gauss_markov(meas, base, set(), model, (None, 2, False), y, RATE, {}, None) is None
