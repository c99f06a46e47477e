"""EDF and intervals: NIST SP 1065 Table 5 (allantools), Greenhall's EDF, and Monte Carlo of the estimator."""

import numpy as np
import pytest
from scipy.stats import chi2

from companion.allan.adev import oavar
from companion.allan.confidence import adev_ci, edf_model, edf_simple, oavar_covariance
from companion.sim.synth import synthesize_axis


@pytest.mark.parametrize("alpha", [2, 1, 0, -1, -2])
def test_edf_simple_equals_allantools(alpha):
    allantools = pytest.importorskip("allantools")
    ours = edf_simple(1001, [1, 3, 10, 100, 300], alpha)
    ref = [allantools.edf_simple(1001, m, alpha) for m in (1, 3, 10, 100, 300)]
    assert ours == pytest.approx(ref, rel=1e-12)


@pytest.mark.parametrize("term,alpha", [({"effect": "bias_instability", "B": 1.0}, -1),
                                        ({"effect": "random_walk", "K": 1.0}, -2),
                                        ({"effect": "white_noise", "N": 1.0}, 0),
                                        ({"effect": "quantization", "Q": 1.0}, 2)])
def test_edf_model_close_to_greenhall_for_pure_power_laws(term, alpha):
    allantools = pytest.importorskip("allantools")
    m = np.array([16, 64, 256, 1024])
    ours = edf_model([term], m, 10000, 1.0)
    ref = np.array([allantools.edf_greenhall(alpha=alpha, d=2, m=int(k), N=10001, overlapping=True) for k in m])
    assert ours == pytest.approx(ref, rel=0.06)


def test_covariance_matches_monte_carlo():
    """Variances and neighbour correlations of the OAVAR estimates of white + random-walk noise."""
    terms = [{"effect": "white_noise", "N": 1.0}, {"effect": "random_walk", "K": 0.05}]
    m = np.array([1, 2, 8, 32, 128])
    n, reps = 3000, 600
    rng = np.random.default_rng(5)
    V = np.array([oavar(synthesize_axis(terms, 1.0, n, rng), 1.0, m=m)[1] for _ in range(reps)])
    emp = np.cov(V.T)
    C = oavar_covariance(terms, m, n, 1.0)
    # sampling error of a variance from 600 draws of a skewed estimator: ~ sqrt(2/600) x (kurtosis) -> 20 %
    assert np.diag(emp) / np.diag(C) == pytest.approx(np.ones(len(m)), rel=0.2)
    corr_e = emp[0, 1] / np.sqrt(emp[0, 0] * emp[1, 1])
    corr_m = C[0, 1] / np.sqrt(C[0, 0] * C[1, 1])
    assert corr_m == pytest.approx(corr_e, abs=0.1) and corr_m > 0.3  # neighbours are strongly correlated


def test_adev_ci_is_the_chi_square_interval():
    lo, hi = adev_ci(np.array([2.0]), np.array([10.0]), 0.95)
    assert lo[0] == pytest.approx(2.0 * np.sqrt(10 / chi2.ppf(0.975, 10)))
    assert hi[0] == pytest.approx(2.0 * np.sqrt(10 / chi2.ppf(0.025, 10)))
    assert lo[0] < 2.0 < hi[0]


def test_ci_coverage_white_noise():
    """The 95 % ADEV interval covers the true ADEV about 95 % of the time (1000 trials; binomial sd 0.7 %)."""
    rng = np.random.default_rng(11)
    term = {"effect": "white_noise", "N": 1.0}
    m = np.array([4, 64, 256])
    edf = edf_model([term], m, 2000, 1.0)
    truth = np.sqrt(1.0 / m)
    hits = np.zeros(len(m))
    for _ in range(1000):
        _, av, _, _ = oavar(synthesize_axis([term], 1.0, 2000, rng), 1.0, m=m)
        lo, hi = adev_ci(np.sqrt(av), edf)
        hits += (lo <= truth) & (truth <= hi)
    assert np.all(hits / 1000 > 0.93) and np.all(hits / 1000 < 0.975), hits / 1000


def test_flicker_sampling_excess_matches_the_synthesised_flicker():
    """The sampled flicker's AVAR over the plateau at the first cluster sizes: the formula against the mean of
    simulated flicker records (companion.sim.synth, spectral shaping to the Nyquist frequency)."""
    from companion.allan.confidence import flicker_sampling_excess
    from companion.sim.synth import flicker

    m = np.array([1, 2, 4])
    ex = flicker_sampling_excess(m)
    plateau = 2.0 * np.log(2.0) / np.pi
    sim = np.mean([oavar(flicker(1.0, 1.0, 1 << 16, np.random.default_rng(s)), 1.0, m=m)[1] for s in range(6)],
                  axis=0) / plateau - 1.0
    assert ex[0] == pytest.approx(0.189, abs=0.002) and ex[1] == pytest.approx(0.0887, abs=0.002)
    assert sim == pytest.approx(ex, abs=0.012)  # the simulated mean scatters by ~0.005
    assert flicker_sampling_excess([200])[0] == 0.0 and np.all(np.diff(ex) < 0)


def _brute_force_cov(terms, m, n, rate_hz):
    """Cov of the OAVAR estimates from the matrices themselves: second-difference operators D_m on the phase,
    the phase's generalised covariance Gamma_ij = sum_terms G(j - i) (+ Q^2 on the diagonal), and
    Cov(v_m, v_m') = 2 ||D_m Gamma D_m'^T||_F^2 / (4 tau^2 tau'^2 M M') (no lag sums, no Riemann step)."""
    from companion.allan.confidence import _gcov

    tau0 = 1.0 / rate_hz
    n_phase = n + 1
    h = np.arange(n_phase)[None, :] - np.arange(n_phase)[:, None]
    gamma = np.zeros((n_phase, n_phase))
    for t in terms:
        if t["effect"] == "quantization":
            gamma += t["Q"] ** 2 * np.eye(n_phase)
        elif t["effect"] != "ramp":  # deterministic: no covariance of its own, the cross term below
            gamma += _gcov(t, h, tau0)
    ops = []
    for k in m:
        M = n_phase - 2 * k
        D = np.zeros((M, n_phase))
        i = np.arange(M)
        D[i, i], D[i, i + k], D[i, i + 2 * k] = 1.0, -2.0, 1.0
        ops.append(D)
    tau = np.asarray(m) * tau0
    r2 = sum(t["R"] ** 2 for t in terms if t["effect"] == "ramp")
    out = np.zeros((len(m), len(m)))
    gd = [gamma @ D.T for D in ops]
    for a, Da in enumerate(ops):
        for b, Db in enumerate(ops):
            c = Da @ gd[b]
            # a ramp R adds R tau^2 to every second difference: + 4 (R tau_a^2)(R tau_b^2) 1' D_a Gamma D_b' 1
            v = 2.0 * np.sum(c * c) + 4.0 * r2 * tau[a] ** 2 * tau[b] ** 2 * np.sum(c)
            out[a, b] = v / (4 * tau[a] ** 2 * tau[b] ** 2 * Da.shape[0] * Db.shape[0])
    return out


@pytest.mark.parametrize("seed", range(2))
def test_covariance_equals_the_matrix_computation_for_any_record_length(seed):
    """The lag sums (remembered per pair geometry and term shapes, with the record length as a factor) equal
    the covariance computed from the difference matrices, for a first record length, for others that reuse
    what the first remembered, and for one where the longest clusters' lags reach the record's ends.
    Quantization, white and random-walk noise have short memory: the sums are exact. Long-memory terms
    (flicker, Gauss-Markov, a sinusoid, filtered white noise) are summed over a truncated tail: within 2 %."""
    from companion.allan import confidence

    rng = np.random.default_rng(seed)
    rate = 50.0
    short = [{"effect": "quantization", "Q": float(10 ** rng.uniform(-4, -2))},
             {"effect": "white_noise", "N": float(10 ** rng.uniform(-3, -2))},
             {"effect": "random_walk", "K": float(10 ** rng.uniform(-4, -3))},
             {"effect": "ramp", "R": 0.0}]
    long_ = [{"effect": "bias_instability", "B": float(10 ** rng.uniform(-4, -3))},
             {"effect": "gauss_markov", "sigma": float(10 ** rng.uniform(-3, -2)), "tau_c": 0.3},
             {"effect": "sinusoid", "amplitude": 1e-3, "freq_hz": 3.0}]
    if seed % 2:
        short[0] = {"effect": "quantization", "Q": 0.0}
        long_[0] = dict(short[1], filter_hz=8.0, sample_hz=rate)  # filtered white noise
    m = np.array([1, 2, 4, 8, 16, 32])  # m < 64: the lag sums take every lag (no Riemann step)
    for terms, tol in ((short, 1e-9), (short[1:] + long_, 0.01)):
        confidence._PAIR_FORMS.clear()
        for n in (300, 360, 100):  # 100: the longest clusters' lags reach the record's ends
            ours = oavar_covariance(terms, m, n, rate)
            ref = _brute_force_cov(terms, m, n, rate)
            d = np.sqrt(np.outer(np.diag(ref), np.diag(ref)))
            assert np.max(np.abs(ours - ref) / d) < tol  # in units of the estimates' standard deviations
        assert len(confidence._PAIR_FORMS) > 0


@pytest.mark.soak
def test_covariance_of_the_longest_clusters_and_a_ramp_equals_the_matrix_computation():
    """Where the record clips the lags (the longest clusters: a few clusters left) the pair counts change
    over the number of clusters, not over m; summed with a Riemann step of m/32 the longest point's variance
    under a ramp came out 37 % low and its correlation with the next point above 1, and a ramp's interval
    covered the truth in 11 of 20 records. White noise and a ramp (a warm-up), octave clusters to half the
    record (m >= 64: the Riemann step): the covariance of the matrices, within 1 % of each point's sd."""
    rate, n = 10.0, 1033
    terms = [{"effect": "white_noise", "N": 1.05e-4}, {"effect": "ramp", "R": 1.9e-5}]
    m = np.array([1, 2, 4, 8, 16, 32, 64, 128, 256, 512])
    ours = oavar_covariance(terms, m, n, rate)
    ref = _brute_force_cov(terms, m, n, rate)
    d = np.sqrt(np.outer(np.diag(ref), np.diag(ref)))
    assert np.max(np.abs(ours - ref) / d) < 0.01, np.round((ours - ref) / d, 3)
    assert np.linalg.eigvalsh(ours / d).min() > -1e-9  # a covariance


def test_remembered_rows_give_the_covariance_of_a_fresh_computation(monkeypatch):
    """The unit-term rows are remembered per pair geometry and term shape: after a fit step changes one term's
    shape (a Gauss-Markov tau_c) the other terms' rows are looked up, and the covariance is bit for bit the one
    computed from nothing; so it is where the byte budget clears the rows in the middle of a matrix. Both
    equal the difference-matrix construction (within the Riemann sum's 1 %)."""
    from companion.allan import confidence

    rate, n = 50.0, 400
    m = np.array([1, 2, 4, 8, 16, 64])  # 64: the Riemann step (m / 32) and its gathered grid
    base = [{"effect": "white_noise", "N": 2e-3, "filter_hz": 8.0, "sample_hz": rate},
            {"effect": "random_walk", "K": 3e-4}, {"effect": "gauss_markov", "sigma": 4e-3, "tau_c": 0.3}]
    moved = [dict(t, tau_c=0.5) if t["effect"] == "gauss_markov" else t for t in base]

    def fresh(terms):
        confidence._PAIR_FORMS.clear()
        confidence.forget_rows()
        return oavar_covariance(terms, m, n, rate)

    fresh(base)
    confidence._PAIR_FORMS.clear()  # the forms change with tau_c anyway: only the rows are looked up
    reused = oavar_covariance(moved, m, n, rate)
    assert np.array_equal(reused, fresh(moved))
    monkeypatch.setattr(confidence._UNIT_ROWS, "max_bytes", 4096)  # a few rows: cleared mid-matrix
    assert np.array_equal(fresh(moved), reused)
    ref = _brute_force_cov(moved, m, n, rate)
    d = np.sqrt(np.outer(np.diag(ref), np.diag(ref)))
    assert np.max(np.abs(reused - ref) / d) < 0.01
