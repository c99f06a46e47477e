"""The log's rate rounding (int16 mrad/s RAW_IMU, say) as a white term with no free parameter:
N_q = LSB sqrt(tau0 / 12) (:mod:`companion.allan.lsb`), added before any explanation is weighed when it
lowers the deviance of the unrecalibrated model by more than chi^2_1(1 - ALPHA)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

from companion.allan.lsb import DITHER_RATIO
from companion.gap import explain
from companion.gap.candidates import fit_terms
from companion.gap.likelihood import Measured
from companion.gap.scoring import ALPHA

#: a value within LSB_REL_TOL x 100 = 0.1 step of the grid counts as on it (round-off of a scaled integer)
LSB_REL_TOL = 1e-3
#: share of the values that must sit on the grid for the step to be the data's LSB
LSB_ON_GRID = 0.999
#: values read for the step (the grid shows in far fewer; bounds the cost of np.unique)
LSB_MAX_VALUES = 200_000


def delta_crit(k: int) -> float:
    """The level a term with ``k`` parameters and no search must pass: chi^2_k(1 - ALPHA)."""
    return float(stats.chi2.isf(ALPHA, max(k, 1)))


def detect_lsb(y, rel_tol: float = LSB_REL_TOL) -> float | None:
    """The quantisation step of ``y`` if (nearly) all values are integer multiples of one step, else None."""
    y = np.asarray(y, dtype=float)
    if y.size < 100:
        return None
    u = np.unique(y[: min(y.size, LSB_MAX_VALUES)])
    if u.size < 3 or u.size > y.size // 4:
        return None
    d = np.diff(u)
    step = float(np.min(d[d > 0]))
    k = (u - u[0]) / step
    if np.mean(np.abs(k - np.round(k)) < rel_tol * 100) < LSB_ON_GRID:
        return None
    return step


@dataclass
class RateRounding:
    """What the rate-rounding check found."""

    #: the JSON record (lsb, N_q, noise per sample in LSB, dithered, added, delta_dev)
    info: dict
    #: the white term N_q to add, held at its value (None: not added)
    term: dict | None = None
    #: the entry of ``added`` that names it
    added: dict | None = None
    note: str | None = None


def rate_rounding(meas: Measured, terms0, lsb: float | None, y_all, rate_hz: float, axis: str) -> RateRounding | None:
    """The rate rounding to ``lsb`` (None: detected from the values) weighed against the model ``terms0`` held
    at its values. None when there is no step or the model has its own quantisation term."""
    if lsb is None:
        lsb = detect_lsb(y_all)
    if not lsb or any(t["effect"] == "quantization" for t in terms0):
        return None
    N_q = lsb * math.sqrt(1.0 / (12.0 * rate_hz))
    sigma = float(np.std(np.diff(np.asarray(y_all, dtype=float))) / math.sqrt(2.0))
    q = {"lsb": lsb, "N_q": N_q, "sigma_sample_lsb": sigma / lsb, "dithered": sigma >= DITHER_RATIO * lsb,
         "added": False}
    out = RateRounding(info=q)
    qterm = {"effect": "white_noise", "N": N_q}
    if not q["dithered"]:
        out.note = (f"samples rounded to LSB {lsb:.4g}: noise per sample {sigma / lsb:.2f} LSB < "
                    f"{DITHER_RATIO} LSB, not dithered: the rounding error follows the signal, short-tau "
                    "ADEV describes the quantiser, not the sensor; no quantisation term is added")
        return out
    if not terms0:
        return out
    current = [dict(t) for t in terms0]
    d_without = fit_terms(meas, current, fixed=range(len(current)), intervals=False).dev
    d_with = fit_terms(meas, current + [qterm], fixed=range(len(current) + 1), intervals=False).dev
    q["delta_dev"] = d_without - d_with
    if d_without - d_with > delta_crit(1):
        q["added"] = True
        out.term = qterm
        out.added = {"effect": "quantization", "form": "rate_lsb", "lsb": lsb, "N": N_q, "model_term": dict(qterm),
                     "explanation": explain.explain_rate_quantization(lsb, N_q, axis)}
    else:
        out.note = (f"rate rounding to LSB {lsb:.4g} adds white noise N_q = {N_q:.3g}; it does not "
                    "change the fit measurably (indistinguishable from the model's N)")
    return out
