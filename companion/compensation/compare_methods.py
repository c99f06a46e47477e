"""Run the three compensation methods of Shi et al. on one gyro series and compare Allan deviations.

method 1 ``stf``:     model L (eq. (3)-(4)) + strong tracking Kalman filter  (:class:`STF`)
method 2 ``srukf``:   model NL (eq. (5)-(6)) + square-root UKF              (:class:`SRUKF`)
method 3 ``srrsukf``: model NL + square-root risk-sensitive UKF (eq. (15))  (:class:`SRRSUKF`)

All three start from the same least-squares ARIMA(1,1,1) fit (:func:`fit_arima111`). The compensated
series is the filtered estimate x_k of eq. (4): the gyro output with the white measurement noise V_k
filtered out and the ARIMA-modelled error kept.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from companion.allan.adev import oadev
from companion.compensation.arima import ArimaParams, fit_arima111
from companion.compensation.srrsukf import SRRSUKF
from companion.compensation.srukf import SRUKF
from companion.compensation.stf import STF
from companion.errors import CompanionError

FILTERS = {"stf": STF, "srukf": SRUKF, "srrsukf": SRRSUKF}
METHODS = tuple(FILTERS)


@dataclass
class MethodResult:
    name: str
    label: str
    x: np.ndarray  # compensated series, same unit as the input
    tau: np.ndarray
    adev: np.ndarray
    seconds: float
    factor_valid: bool
    min_diag: float
    extra: dict = field(default_factory=dict)

    @property
    def samples_per_s(self) -> float:
        return self.x.shape[0] / self.seconds if self.seconds > 0 else float("inf")


@dataclass
class CompensationResult:
    rate_hz: float
    params: ArimaParams
    raw_tau: np.ndarray
    raw_adev: np.ndarray
    methods: dict  # name -> MethodResult

    def to_json(self, axis: str) -> dict:
        out = {
            "axis": axis,
            "rate_hz": self.rate_hz,
            "samples": int(next(iter(self.methods.values())).x.shape[0]) if self.methods else 0,
            "arima": {**self.params.as_dict(), "theta": self.params.theta,
                      "note": "phi, delta1, delta2, R in internal units: physical = offset + scale * value"},
            "raw": {"tau": self.raw_tau.tolist(), "adev": self.raw_adev.tolist()},
            "methods": {},
        }
        for name, m in self.methods.items():
            out["methods"][name] = {
                "label": m.label,
                "tau": m.tau.tolist(),
                "adev": m.adev.tolist(),
                "adev_ratio": (m.adev / self.raw_adev).tolist(),
                "seconds": m.seconds,
                "samples_per_s": m.samples_per_s,
                "factor_valid": m.factor_valid,
                "min_factor_diagonal": m.min_diag,
                **m.extra,
            }
        return out


def compensate(z, rate_hz: float, methods=METHODS, params: ArimaParams | None = None, fit_samples: int = 200_000,
               progress=None, tau_spec="octave", split: str = "auto") -> CompensationResult:
    """Fit the ARIMA model (unless ``params`` is given), run each method, and compute ADEVs.

    ``progress(name, done, total)`` is called periodically during each filter run; ``split`` is passed to
    :func:`fit_arima111`.
    """
    z = np.asarray(z, dtype=float)
    if z.ndim != 1:
        raise CompanionError("compensation needs a single series (one axis)")
    if not np.all(np.isfinite(z)):
        raise CompanionError("the series contains NaN or infinite values")
    if not (rate_hz > 0 and np.isfinite(rate_hz)):
        raise CompanionError(f"invalid sample rate {rate_hz!r} Hz")
    unknown = [m for m in methods if m not in FILTERS]
    if unknown:
        raise CompanionError(f"unknown method {unknown[0]!r}; expected one of {', '.join(METHODS)}")
    if params is None:
        params = fit_arima111(z, max_samples=fit_samples, split=split)
    raw_tau, raw_adev, m_sizes, _ = oadev(z, rate_hz, spec=tau_spec)
    results = {}
    for name in methods:
        f = FILTERS[name](params)
        cb = None if progress is None else (lambda done, total, _n=name: progress(_n, done, total))
        t0 = time.perf_counter()
        x = f.run(z, progress=cb)
        seconds = time.perf_counter() - t0
        tau, adev, _, _ = oadev(x, rate_hz, m=m_sizes)
        extra = {}
        if name == "stf":
            extra["fading_steps"] = f.fading_steps
        else:
            extra["phi_final"] = float(f.x[2])
        if name == "srrsukf":
            extra["rs_skipped"] = f.rs_skipped
        results[name] = MethodResult(name, f.label, x, tau, adev, seconds, f.factor_valid(), float(f.min_diag), extra)
    return CompensationResult(rate_hz, params, raw_tau, raw_adev, results)
