"""The ``draws`` mode of benchmarks/bench_fit.py: random N/B/K records, every term found or bounded.

``python -m benchmarks.bench_fit draws [draws=100] [set=0]`` and ``... draws null [draws=100] [set=0]``.
Random N/B/K, each with a region where it dominates (N log-uniform 2e-4..3e-3 rad/s/sqrt(Hz), the AVAR
crossings N-B at 0.5-20 s and B-K at max(15 x that, 50)-600 s), 2 h at 50 Hz: terms found and coverage of the
95 % intervals (a missing term counts as not covered), also split by the term's expected evidence
(:func:`evidence`) and by whether it is detectable at all (:func:`detectable`, judged without any fit). A term
the fit leaves out gets a 95 % upper bound: the fit's (:func:`companion.allan.fit.upper_bounds`, the covariance
evaluated at the bound; what ``companion analyze`` reports) and the online report's rule
(:func:`companion.estimators.online_report.bounds_for_fit`, evaluated at the fitted model); the benchmark says whether
each holds. ``null``: the same N and B with K = 0, how often a random walk is invented. The set number draws a
different set: parameters from seed 22 + set, records from 10000 + 1000 set + d.

Target: 95 % intervals covering the truth in about 95 % of draws; K invented in about 0 of the null draws.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from companion.allan.adev import cluster_sizes, oavar
from companion.allan.confidence import edf_simple
from companion.allan.fit import fit_avar

NAMES = {"N": "white_noise", "B": "bias_instability", "K": "random_walk"}
FS = 50.0  #: Hz, the draws' rate
SAMPLES = int(2 * 3600 * FS)  #: 2 h: long enough for every term to dominate somewhere
STRONG_LAMBDA = 9.0  #: expected evidence of a 3-sigma effect: "found" is judged where lambda >= 9
FLICKER_PLATEAU = 0.4413  #: 2 ln2 / pi: the flicker floor of AVAR in units of B^2, which sets the crossings


def evidence(terms, effect, tau, m, n, fs):
    """Expected evidence for ``effect`` in a record made of ``terms``: the noncentrality
    lambda = |P_perp C^-1/2 a theta|^2 of the chi^2 drop its column brings (the GLS with the true covariance C,
    the other terms' columns projected out). A term with lambda ~ 3 is a 1.7-sigma effect: any test on the
    AVAR misses it about half the time, so "found" is judged where lambda >= 9 (3 sigma)."""
    from companion.allan.confidence import oavar_covariance
    from companion.allan.fit import _columns, _Problem
    from companion.allan.terms import avar_model

    mod = avar_model(terms, tau)
    sc = float(np.median(mod))
    prob = _Problem(tau, mod / sc, oavar_covariance(terms, m, n, fs) / sc**2, None, 1.0 / fs)
    others = [t["effect"] for t in terms if t["effect"] != effect]
    t = next(t for t in terms if t["effect"] == effect)
    p = {"white_noise": "N", "bias_instability": "B", "random_walk": "K"}[effect]
    q, _ = np.linalg.qr(prob._w(_columns(others, [], tau)))
    a = prob._w(_columns([effect], [], tau))[:, 0] * t[p] ** 2 / sc
    r = a - q @ (q.T @ a)
    return float(r @ r)


def detectable(terms, effect, m, n, fs):
    """Whether ``effect`` is detectable at all in a record of ``n`` samples made of ``terms``, judged without
    any fit and without the record's realisation: at some octave cluster time up to a tenth of the record (the
    longest a single record resolves, EDF ~ 10 there; the fit's record rule, RESOLVE_RECORD_FACTOR) the 95 %
    band of the Allan variance estimate with the term lies wholly above the 95 % band without it (bands
    chi^2(EDF) / EDF of the expected AVAR, EDF from the true noise mix, :func:`edf_model`). Where the bands
    overlap at every such tau, no estimator can tell the term from its absence in a sizeable share of records;
    the honest output there is a bound. Returns (detectable, the tau with the widest separation, separation =
    lower end with / upper end without)."""
    from companion.allan.confidence import edf_model
    from companion.allan.special import chi2_ppf
    from companion.allan.terms import avar_model

    m = np.asarray(m)
    m = m[m / fs <= n / fs / 10.0]
    tau = m / fs
    rest = [t for t in terms if t["effect"] != effect]
    v1, v0 = avar_model(terms, tau), avar_model(rest, tau)
    e1, e0 = edf_model(terms, m, n, fs), edf_model(rest, m, n, fs)
    lo1 = v1 * e1 / np.array([chi2_ppf(0.975, e) for e in e1])
    hi0 = v0 * np.array([chi2_ppf(0.975, e) for e in e0]) / e0
    sep = lo1 / hi0
    i = int(np.argmax(sep))
    return bool(sep[i] > 1.0), float(tau[i]), float(sep[i])


@dataclass
class Draw:
    """One draw's truth (SI) and the B-K crossing it was made with."""

    truth: dict
    t_bk: float

    @property
    def terms(self) -> list[dict]:
        return [{"effect": NAMES[p], p: v} for p, v in self.truth.items()]


@dataclass
class Record:
    """The measured Allan variance of one draw and the fit of it."""

    tau: np.ndarray
    avar: np.ndarray
    fit: object


@dataclass
class Tally:
    """Counts per parameter over the draws."""

    found: dict = field(default_factory=lambda: {p: 0 for p in NAMES})
    inside: dict = field(default_factory=lambda: {p: 0 for p in NAMES})
    zero: dict = field(default_factory=lambda: {p: 0 for p in NAMES})  # found, interval reaching 0: a bound
    held: dict = field(default_factory=lambda: {p: [0, 0, 0] for p in NAMES})  # left out: n, fit's / rule's bound holds
    strong: dict = field(default_factory=lambda: {p: [0, 0, 0] for p in NAMES})  # lambda >= 9: n, found, covered
    det: dict = field(default_factory=lambda: {p: [0, 0, 0] for p in NAMES})  # detectable: n, found, covered
    undet: dict = field(default_factory=lambda: {p: [0, 0, 0, 0] for p in NAMES})  # ... + left out, bound holds
    missing: list = field(default_factory=list)
    t_fit: list = field(default_factory=list)
    t_bound: list = field(default_factory=list)


def draw_truth(rng, null: bool) -> Draw:
    """Every term visible in 2 h: white meets the flicker floor at tau_NB in 0.5-20 s, the floor meets the random
    walk at tau_BK in max(15 tau_NB, 50)-600 s (AVAR crossings). ``null``: no random walk."""
    nv = 10 ** rng.uniform(math.log10(2e-4), math.log10(3e-3))
    t_nb = 10 ** rng.uniform(math.log10(0.5), math.log10(20.0))
    bv = nv / math.sqrt(FLICKER_PLATEAU * t_nb)
    t_bk = 10 ** rng.uniform(math.log10(max(15 * t_nb, 50.0)), math.log10(600.0))
    truth = {"N": nv, "B": bv, "K": math.sqrt(3 * FLICKER_PLATEAU) * bv / math.sqrt(t_bk)}
    if null:
        truth.pop("K")
    return Draw(truth, t_bk)


def measure_and_fit(draw: Draw, seed: int, m, edf, tally: Tally) -> Record:
    """Synthesise the draw's record, measure its overlapping AVAR and fit it (timed)."""
    from companion.sim.synth import synthesize_axis

    y = synthesize_axis(draw.terms, FS, SAMPLES, np.random.default_rng(seed))
    tau, av = oavar(y, FS, m=m)[:2]
    t0 = time.perf_counter()
    fr = fit_avar(tau, av, edf, n=SAMPLES, rate_hz=FS, m=m)
    tally.t_fit.append(time.perf_counter() - t0)
    return Record(tau, av, fr)


def count_null(draw: Draw, rec: Record, tally: Tally) -> None:
    """A null draw: a random walk found is invented; N and B found and covered."""
    tally.found["K"] += rec.fit.term("random_walk") is not None
    for p in ("N", "B"):
        t = rec.fit.term(NAMES[p])
        tally.found[p] += t is not None
        tally.inside[p] += t is not None and t["ci95"][p][0] <= draw.truth[p] <= t["ci95"][p][1]


def left_out_bounds(rec: Record, m, edf, tally: Tally):
    """The fit's and the online report's 95 % upper bounds of the terms the fit left out (timed)."""
    from companion.allan.fit import upper_bounds
    from companion.estimators.online_report import bounds_for_fit

    t0 = time.perf_counter()
    bounds = (upper_bounds(rec.fit, rec.tau, rec.avar, n=SAMPLES, rate_hz=FS, m=m),
              bounds_for_fit(rec.fit, rec.tau, rec.avar, edf, FS, SAMPLES))
    tally.t_bound.append(time.perf_counter() - t0)
    return bounds


def count_left_out(d, p, draw, bounds, lam, det_info, tally: Tally) -> None:
    """A term the fit left out: does each bound hold, and why it may be missing (printed later)."""
    e = NAMES[p]
    ok, tau_s, sep = det_info
    b, b_rep = (next((x for x in bs if x["effect"] == e), None) for bs in bounds)
    truth = draw.truth
    tally.held[p][0] += 1
    tally.held[p][1] += b is not None and truth[p] <= b[p]
    tally.held[p][2] += b_rep is not None and truth[p] <= b_rep[p]
    if not ok:
        tally.undet[p][3] += b is not None and truth[p] <= b[p]
    tally.missing.append((d, p, {k: f"{v:.2g}" for k, v in truth.items()}, f"t_BK {draw.t_bk:.0f} s",
                          f"lambda {lam:.1f}", ("detectable" if ok else "not detectable")
                          + f" (bands {sep:.2f} at {tau_s:.3g} s)",
                          "bound " + ("-" if b is None else f"{b[p] / truth[p]:.2f} x truth")
                          + " (report rule " + ("-" if b_rep is None else f"{b_rep[p] / truth[p]:.2f}") + ")"))


def count_found(p, t, truth, lam, ok, tally: Tally) -> None:
    """A term the fit kept: its interval, split by evidence and detectability."""
    strong = lam >= STRONG_LAMBDA
    lo, hi = t["ci95"][p]
    covers = lo <= truth[p] <= hi
    tally.found[p] += 1
    tally.strong[p][1] += strong
    tally.zero[p] += not lo > 0
    tally.inside[p] += covers
    tally.strong[p][2] += strong and covers
    group = tally.det if ok else tally.undet
    group[p][1] += 1
    group[p][2] += covers


def count_draw(d, draw: Draw, rec: Record, m, edf, tally: Tally) -> None:
    """Every parameter of one (non-null) draw: found and covered, or left out and bounded."""
    bounds = None
    for p, e in NAMES.items():
        t = rec.fit.term(e)
        lam = evidence(draw.terms, e, rec.tau, m, SAMPLES, FS)
        tally.strong[p][0] += lam >= STRONG_LAMBDA
        det_info = detectable(draw.terms, e, m, SAMPLES, FS)
        (tally.det if det_info[0] else tally.undet)[p][0] += 1
        if t is None:
            if bounds is None:
                bounds = left_out_bounds(rec, m, edf, tally)
            count_left_out(d, p, draw, bounds, lam, det_info, tally)
            continue
        count_found(p, t, draw.truth, lam, det_info[0], tally)


def print_null(draws: int, fresh: int, tally: Tally) -> None:
    print(f"{draws} draws of N and B with K = 0 (set {fresh}), 2 h at 50 Hz")
    print(f"  K invented in {tally.found['K']}/{draws}")
    for p in ("N", "B"):
        print(f"  {p}: found {tally.found[p]}/{draws}, 95 % interval covers the truth in {tally.inside[p]}/{draws}")


def print_tally(draws: int, fresh: int, tally: Tally) -> None:
    t = tally
    print(f"{draws} random N/B/K draws (set {fresh}), 2 h at 50 Hz; fit median {np.median(t.t_fit):.2f} s, "
          f"bounds of the left-out terms median {np.median(t.t_bound) if t.t_bound else 0:.2f} s per draw")
    for p in NAMES:
        print(f"  {p}: found {t.found[p]}/{draws}, 95 % interval covers the truth in {t.inside[p]}/{draws} "
              f"({100 * t.inside[p] / draws:.0f} %); where its expected evidence lambda >= 9: found "
              f"{t.strong[p][1]}/{t.strong[p][0]}, covers {t.strong[p][2]}/{t.strong[p][0]}"
              + (f"; found with an interval reaching 0 (analyze: a bound) in {t.zero[p]}" if t.zero[p] else "")
              + (f"; left out in {t.held[p][0]}, its 95 % upper bound above the truth in {t.held[p][1]} "
                 f"(the online report's rule: {t.held[p][2]})" if t.held[p][0] else ""))
        dd, uu = t.det[p], t.undet[p]
        print(f"     detectable (bands apart at some tau <= T/10) in {dd[0]}: found {dd[1]}/{dd[0]}, covers "
              f"{dd[2]}/{dd[0]}; not detectable in {uu[0]}: found {uu[1]} (covers {uu[2]}), left out "
              f"{uu[0] - uu[1]} (bound above the truth {uu[3]}/{uu[0] - uu[1]}); value covers or bound holds: "
              f"{dd[2] + uu[2] + uu[3] + (t.held[p][1] - uu[3])}/{draws}")
    for x in t.missing[:30]:
        print("  missing:", x)


def run_draws(args):
    """``draws [null] [draws=100] [set=0]``: the module docstring."""
    null = bool(args) and args[0] == "null"
    args = args[1:] if null else args
    draws = int(args[0]) if args else 100
    fresh = int(args[1]) if len(args) > 1 else 0
    m = cluster_sizes(SAMPLES, "octave")
    edf = edf_simple(SAMPLES + 1, m, 0)
    rng = np.random.default_rng(22 + fresh)
    tally = Tally()
    for d in range(draws):
        draw = draw_truth(rng, null)
        rec = measure_and_fit(draw, 10_000 + 1000 * fresh + d, m, edf, tally)
        if null:
            count_null(draw, rec, tally)
        else:
            count_draw(d, draw, rec, m, edf, tally)
    (print_null if null else print_tally)(draws, fresh, tally)
