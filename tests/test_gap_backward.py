"""The backward step for added effects (companion.gap.workflow._drop_unneeded): an effect a later step made
unnecessary is dropped at the level it passed when added; an effect the data need is kept."""

import numpy as np

from companion.gap.candidates import fit_terms
from companion.gap.compare import measure
from companion.gap.workflow import _drop_unneeded
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
