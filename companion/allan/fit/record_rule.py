"""The record rule: a long-tau term (bias instability, rate random walk) is reported only where the record is
long enough to resolve it (RESOLVE_RECORD_FACTOR x the shortest cluster time from which it dominates, at least
RESOLVE_MIN_RECORD_S); otherwise it stays in the model as a nuisance term and the caller reports a bound."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from companion.allan.fit.constants import RESOLVE_EFFECTS, RESOLVE_MIN_RECORD_S, RESOLVE_RECORD_FACTOR
from companion.allan.fit.fit_result import FitResult
from companion.allan.terms import avar_model, avar_term

#: the share grid spans this many decades of cluster time above tau0 (a term dominating later dominates nowhere)
_SHARE_DECADES = 9
#: points of that grid
_SHARE_POINTS = 2000


def dominates_from(terms, tau0: float) -> dict[str, float]:
    """For each of ``RESOLVE_EFFECTS`` in ``terms`` (fitted, SI): the shortest tau (>= tau0) from which it is
    at least half of the model AVAR, or, where it never is, the tau where its share is largest: a bias
    instability between white noise and a rate random walk may never reach half anywhere, yet it is best
    seen (and only resolvable) where its share peaks; requiring half there would make it a bound on any record
    and move its share into K."""
    plain = [{k: v for k, v in t.items() if k != "ci95"} for t in terms]
    grid = np.exp(np.linspace(math.log(tau0), math.log(tau0) + math.log(10.0**_SHARE_DECADES), _SHARE_POINTS))
    total = avar_model(plain, grid)
    out = {}
    for t in plain:
        if t["effect"] not in RESOLVE_EFFECTS:
            continue
        share = avar_term(t, grid) / np.where(total > 0, total, np.inf)
        dom = np.flatnonzero(share >= min(0.5, float(share.max())))
        out[t["effect"]] = float(grid[dom[0]]) if dom.size and share.max() > 0 else math.inf
    return out


def record_needed(terms, tau0: float) -> dict[str, float]:
    """For each of ``RESOLVE_EFFECTS`` in ``terms`` (fitted, SI): the record length (s) it needs to be
    resolved, RESOLVE_RECORD_FACTOR x the shortest tau from which it dominates (:func:`dominates_from`;
    inf if it never does), at least RESOLVE_MIN_RECORD_S."""
    return _record_for(dominates_from(terms, tau0))


def _record_for(tau_d: dict[str, float]) -> dict[str, float]:
    return {e: max(RESOLVE_RECORD_FACTOR * t, RESOLVE_MIN_RECORD_S) for e, t in tau_d.items()}


def _unresolved_note(effect, record, need, tau_d) -> str:
    return (f"{effect} not resolved: the record ({record:.3g} s) is shorter than the "
            + (f"{need:.3g} s it needs (it dominates the Allan variance only from tau {tau_d:.3g} s, "
               f"and needs that tau within a tenth of the record)"
               if math.isfinite(need) and need > RESOLVE_MIN_RECORD_S
               else f"{need:.3g} s a long-tau term needs at least" if math.isfinite(need)
               else "record it needs (it dominates the Allan variance at no tau)")
            + "; given as an upper bound")


def apply_record_rule(res: FitResult, n, rate_hz, segments) -> FitResult:
    """Step: move the terms the record is too short to resolve from ``terms`` to ``nuisance``, each with a note.

    The rule decides what is reported, not what is modelled: the dropped term stays in the model (its share of
    the curve is there, resolved or not), and the kept terms keep their values and intervals from that model.
    Refitted without it, the kept terms would take up its share wherever it is not negligible (a bias
    instability at 20-45 % of the AVAR moves into N, or into a Gauss-Markov term at the 3-sample edge where it
    mimics the low-pass filter)."""
    if n is None or not rate_hz or not res.terms:
        return res
    record = (max(segments) if segments else n) / float(rate_hz)
    tau_d = dominates_from(res.terms, 1.0 / float(rate_hz))
    needs = _record_for(tau_d)
    drop = {e: need for e, need in needs.items() if need > record}
    if not drop:
        return res
    out = replace(res, terms=[t for t in res.terms if t["effect"] not in drop],
                  nuisance=[t for t in res.terms if t["effect"] in drop], notes=list(res.notes))
    for e, need in drop.items():
        out.notes.append(_unresolved_note(e, record, need, tau_d[e]))
    return out
