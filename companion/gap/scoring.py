"""The one criterion every explanation of a gap is ranked by, and the record of one explanation.

    score(E) = Delta D_E - phi_E penalty(E)      (= D_state - [D_E + phi_E penalty(E)])

i.e. each explanation's deviance plus its overdispersion-scaled penalty (a quasi-likelihood AIC, QAIC, with
the penalty of the documented test levels); the smallest wins.

* Delta D_E = D_state - D_E: the Gamma deviance (-2 ln L + const, :mod:`companion.gap.likelihood`) the
  explanation removes; the state is the model as it stands (model terms held at their values unless a
  previous step recalibrated them; effects added earlier free).
* phi_E >= 1: the overdispersion of that likelihood ratio (the long-tau octave estimates are correlated and
  few in EDF), :func:`companion.gap.candidates.lr_inflation` at the state fit (score-test form) in the
  directions E opens (the unit column of an added effect, of a freed model term); for two directions the
  largest Rao-Scott eigenvalue (conservative: a combination never gains from its correction).
* penalty(E) = the sum of the levels its parts must pass on their own: chi^2_k(1 - ALPHA) for an added
  effect with k parameters (15.1, 18.4), chi^2_1(1 - ALPHA_RECAL) = 10.8 per recalibrated term.

A positive score is the same statement as "the corrected likelihood ratio LR = Delta D_E / phi_E exceeds
the documented level" (Rao and Scott 1981 for the correction; Burnham and Anderson 2002, sec. 2.5, QAIC).
"""

from __future__ import annotations

from dataclasses import dataclass

from scipy import stats

from companion.gap.candidates import MAGNITUDE, N_PARAMS, Fit, lr_inflation, unit_column

#: level an added effect must pass (its score's penalty is chi^2_k(1 - ALPHA))
ALPHA = 1e-4
#: level a recalibrated model term must pass (penalty chi^2_1(1 - ALPHA_RECAL) = 10.8)
ALPHA_RECAL = 1e-3
#: one-parameter limits of two-parameter effects (Gauss-Markov: tau_c >> T is a rate random walk,
#: tau_c << tau0 white noise; IEEE 952 C.6)
NESTED = {"gauss_markov": ("random_walk", "white_noise")}
#: the autopilot's low-pass filter (and the aliasing of the logger's decimation) on the white noise
LOWPASS = "lowpass"
#: a Gauss-Markov term with tau_c below this many samples is the look-alike of a low-pass filter
FILTER_LIKE_SAMPLES = 10.0
#: effects with power at the shortest cluster times, where a fitted low-pass cut-off acts
SHORT_TAU_EFFECTS = ("quantization", "gauss_markov", "sinusoid")


def add_penalty(k: int) -> float:
    """The level an added effect with ``k`` free parameters must pass: chi^2_k(1 - ALPHA)."""
    return float(stats.chi2.isf(ALPHA, max(k, 1)))


#: the level a recalibrated model term must pass, chi^2_1(1 - ALPHA_RECAL) = 10.8
RECAL_PENALTY = float(stats.chi2.isf(ALPHA_RECAL, 1))


@dataclass
class Explanation:
    """One explanation of the gap, fitted from the state: ``effect`` added (or None) and the model terms
    ``recal`` freed (recalibrated)."""

    effect: str | None
    recal: tuple
    fit: Fit
    delta_dev: float
    inflation: float
    penalty: float
    #: for "lowpass": the index of the white_noise term the filter is put on (no term is appended)
    modifies: int | None = None

    @property
    def lr(self) -> float:
        return self.delta_dev / self.inflation

    @property
    def score(self) -> float:
        return self.delta_dev - self.inflation * self.penalty

    @property
    def k(self) -> int:
        return (N_PARAMS.get(self.effect, 1) if self.effect else 0) + len(self.recal)

    def added_term(self) -> dict | None:
        """The term the explanation adds (for "lowpass": the filtered white-noise term)."""
        if not self.effect:
            return None
        return self.fit.terms[self.modifies] if self.modifies is not None else self.fit.terms[-1]

    def changes(self) -> set:
        return ({("add", self.effect)} if self.effect else set()) | {("recal", j) for j in self.recal}

    def label(self, model_terms) -> str:
        parts = [self.effect] if self.effect else []
        for j in self.recal:
            t = model_terms[j]
            parts.append(f"recalibrated {t['effect']} {MAGNITUDE[t['effect']]}")
        return " + ".join(parts)

    def as_dict(self, model_terms) -> dict:
        d = {"explanation": self.label(model_terms), "effect": self.effect,
             "recalibrate": [f"{model_terms[j]['effect']}.{MAGNITUDE[model_terms[j]['effect']]}" for j in self.recal],
             "k": self.k, "delta_dev": self.delta_dev, "inflation": self.inflation, "lr": self.lr,
             "penalty": self.penalty, "score": self.score, "gap": self.fit.gap}
        if self.effect == "temperature":
            t = self.added_term()
            d["params"] = {"coef": t["coef"]}
        elif self.effect == LOWPASS:
            t = self.added_term()
            d["params"] = {"cutoff_hz": t["cutoff_hz"], "order": t.get("order", 2), "N": t["N"]}
        elif self.effect:
            d["params"] = {p: v for p, v in self.fit.terms[-1].items() if p != "effect"}
        if self.recal:
            d["recalibrated"] = {f"{model_terms[j]['effect']}.{MAGNITUDE[model_terms[j]['effect']]}":
                                 {"model": model_terms[j][MAGNITUDE[model_terms[j]['effect']]],
                                  "fitted": self.fit.terms[j][MAGNITUDE[model_terms[j]['effect']]]}
                                 for j in self.recal}
        return d


def make_explanation(meas, state: Fit, held, effect, recal, fit, sigma=None) -> Explanation:
    """The explanation that adds ``effect`` (or none) and frees the model terms ``recal`` from ``state``, fitted
    as ``fit``: its deviance gain, overdispersion in the directions it opens and penalty."""
    dirs = []
    if effect:
        dirs.append(unit_column(fit.terms[-1], meas.tau, meas.rate_hz))
    for j in recal:
        dirs.append(unit_column(state.terms[j], meas.tau, meas.rate_hz))
    phi = lr_inflation(meas, state, None, direction=dirs, sigma=sigma)
    pen = (add_penalty(N_PARAMS[effect]) if effect else 0.0) + RECAL_PENALTY * len(recal)
    return Explanation(effect, tuple(recal), fit, state.dev - fit.dev, phi, pen)
