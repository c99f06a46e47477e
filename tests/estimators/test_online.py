"""Online estimators: streaming == block, bounded state, recovery of known coefficients (simulated)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from companion.allan.adev import avar_nonoverlapping, oavar
from companion.estimators import OctaveBankEstimator, from_state_dict, make_estimator


def white_rw(rng, n, fs, N, K=0.0, bias=0.0):
    """Test-only generator: white rate noise of density N (std N sqrt(fs)) plus rate random walk K."""
    y = rng.normal(0.0, N * np.sqrt(fs), n) + bias
    if K:
        y += np.cumsum(rng.normal(0.0, K * np.sqrt(1.0 / fs), n))
    return y


def test_streaming_equals_block_bitwise():
    rng = np.random.default_rng(11)
    y = white_rw(rng, 50_000, 100.0, 2e-3, 1e-4, bias=0.3)
    a = OctaveBankEstimator(100.0, forgetting_s=60.0)
    a.update(y)
    b = OctaveBankEstimator(100.0, forgetting_s=60.0)
    for v in y[:7001]:
        b.update(v)
    for chunk in np.array_split(y[7001:], 13):
        b.update(chunk)
    assert a.n_samples == b.n_samples == y.size
    assert np.array_equal(a.avar()[1], b.avar()[1])
    assert a.terms() == b.terms()


def test_one_phase_is_classic_nonoverlapping_avar():
    rng = np.random.default_rng(3)
    y = white_rw(rng, 40_000, 50.0, 1e-3, 5e-5)
    est = OctaveBankEstimator(50.0, phases=1)
    est.update(y)
    tau, avar, _ = est.avar()
    t2, a2, _ = avar_nonoverlapping(y, 50.0, m=np.round(tau * 50.0).astype(int))
    assert np.allclose(avar[: t2.size], a2, rtol=1e-9)


def test_full_phases_small_levels_equal_overlapping_avar():
    rng = np.random.default_rng(4)
    y = white_rw(rng, 20_000, 50.0, 1e-3, 5e-5)
    est = OctaveBankEstimator(50.0, phases=8)
    est.update(y)
    tau, avar, _ = est.avar()
    _, a2, _, _ = oavar(y, 50.0, m=[1, 2, 4, 8])  # m <= phases: fully overlapping
    assert np.allclose(avar[:4], a2, rtol=1e-9)


def test_segments_pool_as_the_offline_pooled_avar():
    """Pieces fed with new_segment() between them: at the fully overlapping levels the bank's AVAR equals the
    offline pooled AVAR of the same pieces (companion.allan.pooled, computed independently), a junction
    between pieces with different means adds nothing, and the segment lengths survive a state round trip."""
    from companion.allan.pooled import pooled_oavar

    rng = np.random.default_rng(6)
    pieces = [white_rw(rng, k, 50.0, 1e-3, 5e-5) + off for k, off in ((7000, 0.0), (3000, 0.3), (5000, -0.2))]
    est = OctaveBankEstimator(50.0, phases=8)
    for p in pieces:
        est.new_segment()
        est.update(p)
    _, avar, _ = est.avar()
    _, a2, _, _ = pooled_oavar(pieces, 50.0, m=[1, 2, 4, 8])
    assert np.allclose(avar[:4], a2, rtol=1e-9)
    assert est.segments() == [7000, 3000, 5000]
    b = from_state_dict(json.loads(json.dumps(est.state_dict())))
    assert b.segments() == [7000, 3000, 5000] and np.array_equal(b.avar()[1], avar)
    joined = OctaveBankEstimator(50.0, phases=8)
    joined.update(np.concatenate(pieces))  # without the breaks the steps between the means enter the AVAR
    assert joined.avar()[1][3] > 3 * avar[3]



def test_with_forgetting_the_segment_list_keeps_the_last_twenty_memories():
    """``run`` starts a segment at every still piece, for hours: with forgetting the list stays bounded (a piece
    followed by 20 memories of samples weighs e^-20), the pieces it keeps are the newest ones with their true
    lengths, through a state round trip too; without forgetting every piece is kept."""
    rng = np.random.default_rng(8)
    a = OctaveBankEstimator(50.0, phases=8, forgetting_s=10.0)  # 20 memories: 10,000 samples
    b = OctaveBankEstimator(50.0, phases=8)
    lengths = [int(x) for x in rng.integers(300, 1500, 40)]
    for k, n in enumerate(lengths):
        for est in (a, b):
            est.new_segment()
            est.update(white_rw(rng, n, 50.0, 1e-3))
        if k == 20:
            a = from_state_dict(json.loads(json.dumps(a.state_dict())))
    assert b.segments() == lengths
    kept = a.segments()
    closed = kept[:-1]  # the current piece is not closed yet: trimmed at the next new_segment()
    assert kept == lengths[-len(kept):] and sum(closed[1:]) <= 10_000 < sum(closed)


def test_state_roundtrip_json_and_bounded_size():
    rng = np.random.default_rng(5)
    y = white_rw(rng, 30_000, 200.0, 1e-3)
    a = OctaveBankEstimator(200.0, forgetting_s=100.0)
    a.update(y[:12_345])
    d = json.loads(json.dumps(a.state_dict()))
    b = from_state_dict(d)
    a.update(y[12_345:])
    b.update(y[12_345:])
    assert a.terms() == b.terms()
    c = OctaveBankEstimator(200.0, forgetting_s=100.0)
    c.update(white_rw(rng, 300_000, 200.0, 1e-3))
    assert len(json.dumps(c.state_dict())) < 1.3 * len(json.dumps(a.state_dict())) + 2000


@pytest.mark.parametrize("seed", range(6))
def test_white_and_random_walk_recovered(seed):
    rng = np.random.default_rng(100 + seed)
    fs, N, K = 100.0, 2e-3, 2e-5
    y = white_rw(rng, 200_000, fs, N, K, bias=0.01)
    est = make_estimator("octave", rate_hz=fs, effects=("white_noise", "random_walk"))
    est.update(y)
    t = {d["effect"]: d for d in est.terms()}
    # N: AVAR at tau0 has ~2e5 degrees of freedom -> relative error of N well under 1 %
    assert t["white_noise"]["N"] == pytest.approx(N, rel=0.01)
    assert t["white_noise"]["std"]["N"] < 0.01 * N
    # K from a 2000 s run: few long clusters -> loose statistical tolerance (4 sigma of its own std)
    assert abs(t["random_walk"]["K"] - K) < 4 * t["random_walk"]["std"]["K"] + 0.05 * K


def test_bad_config_is_a_clear_error():
    with pytest.raises(ValueError, match="phases"):
        OctaveBankEstimator(100.0, phases=3)
    with pytest.raises(ValueError, match="effects"):
        OctaveBankEstimator(100.0, effects=("gauss_markov",))
    with pytest.raises(ValueError, match="no setting"):
        make_estimator("octave", rate_hz=100.0, colour="blue")
    with pytest.raises(ValueError, match="kind"):
        make_estimator("kalman", rate_hz=100.0)


def test_non_finite_samples_are_skipped_and_counted():
    est = OctaveBankEstimator(100.0)
    est.update([1.0, float("nan"), 2.0])
    est.update(float("inf"))
    assert est.n_samples == 2 and est.n_rejected == 2


def test_forgetting_tracks_a_change():
    rng = np.random.default_rng(21)
    fs = 100.0
    before = white_rw(rng, 60_000, fs, 1e-3)
    after = white_rw(rng, 60_000, fs, 2e-3)  # N doubles after 600 s
    fast = OctaveBankEstimator(fs, effects=("white_noise", "random_walk"), forgetting_s=60.0)
    keep = OctaveBankEstimator(fs, effects=("white_noise", "random_walk"))
    for est in (fast, keep):
        est.update(before)
        est.update(after)
    n_fast = fast.terms()[0]["N"]
    n_keep = keep.terms()[0]["N"]
    # 600 s after the change the 60 s memory has forgotten it (e^-10); infinite memory sits in between
    assert n_fast == pytest.approx(2e-3, rel=0.03)
    assert 1.4e-3 < n_keep < 1.7e-3


@pytest.mark.parametrize("seed", [0, 1])
def test_default_fit_copes_with_a_line_the_model_lacks(seed):
    """N + flicker B + K plus a 19.7 Hz line of 6e-3 rad/s (as on the ADIS16405 z axes) that the five-term
    model cannot describe: the short-tau levels, with thousands of degrees of freedom, disagree with the
    model. Without the model-error floor the fast fit matched them with N 1.20x, dropped B to 0 and made K
    2-2.8x; with it, N keeps only the part of the line's power that looks white (<= 15 %), B is within 30 %
    (the spread of a flicker estimate over 2.8 h is ~10 % in ln B) and K within a factor 2, or, left out, a
    bound above it (truth from the simulator)."""
    from companion.sim.synth import synthesize_axis

    N, B, K = 6.5e-4, 1.4e-4, 5e-6
    y = synthesize_axis([{"effect": "white_noise", "N": N}, {"effect": "bias_instability", "B": B},
                         {"effect": "random_walk", "K": K}, {"effect": "sinusoid", "amplitude": 6e-3, "freq_hz": 19.7}],
                        100.0, 1_000_000, np.random.default_rng(seed))
    est = make_estimator("octave", rate_hz=100.0, effects=("white_noise", "bias_instability", "random_walk"))
    est.update(y)
    t = {d["effect"]: d for d in est.terms()}
    assert 1.0 <= t["white_noise"]["N"] / N <= 1.15
    assert t["bias_instability"]["B"] == pytest.approx(B, rel=0.30)
    k = t["random_walk"]
    if k.get("bound"):
        # left out, K's 95 % bound by test inversion holds; the line the model lacks enters the points'
        # covariance as model error and widens it (3.8x and 4.3x the truth on seeds 0 and 1)
        assert 1.0 <= k["K"] / K <= 10.0
    else:
        assert 0.5 <= k["K"] / K <= 2.0
