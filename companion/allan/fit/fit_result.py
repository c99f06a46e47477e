"""The result of :func:`companion.allan.fit.fit_avar`."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class FitResult:
    """Result of :func:`fit_avar`. ``terms``: fitted term dicts (SI) each with ``"ci95"``."""

    terms: list[dict]
    tau: np.ndarray
    avar_fit: np.ndarray
    chi2: float = 0.0
    dof: int = 0
    criterion: str = "bic"
    score: float = 0.0
    covariance_mode: str = "full"
    avar_cov: np.ndarray | None = field(default=None, repr=False)
    notes: list[str] = field(default_factory=list)
    model_error: float = 0.0  # relative AVAR model error added per point when the model misfits (0: none)
    filter: dict | None = None  # the low-pass filter modelled in the white-noise term (None: none)
    # terms in the model (avar_fit, avar_cov and the others' intervals include them) that the record is too
    # short to resolve (fit_avar's record rule): not reported; the caller gives their upper bounds
    nuisance: list[dict] = field(default_factory=list)

    def term(self, effect: str) -> dict | None:
        for t in self.terms:
            if t["effect"] == effect:
                return t
        return None

    def to_dict(self) -> dict:
        return {"terms": self.terms, "chi2": self.chi2, "dof": self.dof, "criterion": self.criterion,
                "model_error": self.model_error, "filter": self.filter,
                "score": self.score, "covariance": self.covariance_mode, "notes": list(self.notes)}
