"""What the output quantisation (the LSB of an int16 MAVLink field) does to the noise estimates.

ArduPilot sends RAW_IMU / SCALED_IMU gyro rates rounded to 1 mrad/s. Rounding *rate* samples is not the
IEEE 952 quantization term (that one is angle quantisation, AVAR 3 Q^2 / tau^2, slope -1). When the sensor
noise per sample is large enough to dither the rounding (sigma >~ LSB / 2: the error's dependence on the
signal, exp(-2 pi^2 sigma^2 / LSB^2), is then below 1 %; Widrow & Kollar, *Quantization Noise*, 2008, ch. 4-5),
the rounding error is uniform and white, of variance LSB^2 / 12 per sample: white rate noise with

    N_q^2 = LSB^2 tau0 / 12        (AVAR N_q^2 / tau, slope -1/2),

which simply adds to the sensor's N^2 (sensor N = sqrt(N_fit^2 - N_q^2)). Below that the output is not
dithered: the error follows the slow signal, short-tau ADEV and N are then not estimates of the sensor,
and the report says so instead of pretending.
"""

from __future__ import annotations

import math

import numpy as np

#: sigma / LSB above which the rounding error is taken as white (dithered)
DITHER_RATIO = 0.5


def lsb_report(y, rate_hz: float, lsb: float | None, N_fit: float | None) -> dict | None:
    """Quantisation contribution for one axis: ``None`` when the format has no LSB.

    Returns ``{"lsb", "N_q", "sigma_sample", "dithered", "share_of_N2", "N_sensor", "note"}`` (SI);
    ``sigma_sample`` is the high-frequency noise per sample, std(diff(y)) / sqrt(2).
    """
    if not lsb or lsb <= 0:
        return None
    y = np.asarray(y, dtype=float)
    tau0 = 1.0 / rate_hz
    N_q = lsb * math.sqrt(tau0 / 12.0)
    sigma = float(np.std(np.diff(y)) / math.sqrt(2.0)) if y.size > 2 else 0.0
    dithered = sigma >= DITHER_RATIO * lsb
    out = {"lsb": float(lsb), "N_q": N_q, "sigma_sample": sigma, "dithered": bool(dithered),
           "share_of_N2": None, "N_sensor": None}
    if N_fit and N_fit > 0:
        share = min(N_q**2 / N_fit**2, 1.0)
        out["share_of_N2"] = share
        out["N_sensor"] = math.sqrt(max(N_fit**2 - N_q**2, 0.0))
    if not dithered:
        out["note"] = (f"not dithered: noise per sample {sigma / lsb:.2f} LSB < {DITHER_RATIO} LSB; the rounding "
                       "error follows the signal, N and short-tau ADEV describe the quantiser, not the sensor")
    elif out["share_of_N2"] is not None and out["share_of_N2"] > 0.5:
        out["note"] = f"N dominated by the LSB rounding ({100 * out['share_of_N2']:.0f} % of N^2)"
    elif out["share_of_N2"] is not None:
        out["note"] = f"LSB rounding is {100 * out['share_of_N2']:.0f} % of N^2"
    else:
        out["note"] = ""
    return out
