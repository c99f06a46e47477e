"""Gyro random-error compensation with an ARIMA(1,1,1) model (Shi et al., SR-RSUKF paper).

- :mod:`.arima`: model L / model NL, least-squares initialisation, internal scaling;
- :mod:`.stf`: strong tracking Kalman filter on model L (method 1);
- :mod:`.srukf`: square-root UKF on model NL (method 2);
- :mod:`.srrsukf`: square-root risk-sensitive UKF on model NL (method 3);
- :mod:`.sqrt_ops`: Cholesky rank-1 update/downdate and the QR triangularisation;
- :mod:`.compare_methods`: run the methods on a series and compare Allan deviations.
"""

from companion.compensation.arima import ArimaParams, fit_arima111, simulate_arima111
from companion.compensation.compare_methods import FILTERS, METHODS, CompensationResult, compensate
from companion.compensation.srrsukf import SRRSUKF
from companion.compensation.srukf import SRUKF
from companion.compensation.stf import STF

__all__ = [
    "ArimaParams", "fit_arima111", "simulate_arima111", "STF", "SRUKF", "SRRSUKF",
    "FILTERS", "METHODS", "CompensationResult", "compensate",
]
