"""Does a loaded baseline describe the stream being watched? (A baseline of another message, rate or
sensor scale would compare unlike noise and raise false alarms or hide real ones.)

A baseline is only comparable with the stream it was measured on: the same IMU message (RAW_IMU values
are filtered and int16-rounded, HIGHRES_IMU floats are not), the same rate (N, B, K of a low-passed,
resampled signal change with the rate), the same sensor LSB (the rounding adds white noise) and the same
units (every companion file is SI). :func:`mismatch` names every difference in one line;
:func:`units_mismatch` catches a baseline in other units or of another sensor from the first
estimate (a white-noise density 20x off).
"""

from __future__ import annotations

import math

RATE_TOL = 0.05  # relative rate difference of one stream measured twice (timing jitter), beyond it another stream
LSB_TOL = 0.01  # relative LSB difference of one sensor scale (float rounding), beyond it another scale
N_RATIO_MAX = 20.0  # white noise this many times off the baseline's: other units or another sensor, not wear


def stream_meta(ch) -> dict:
    """The description of a pipeline channel's stream, stored with a learned baseline."""
    return {"message": ch.message, "rate_hz": ch.rate_hz, "gyro_lsb": getattr(ch, "gyro_lsb", None), "units": "SI"}


def mismatch(base: dict | None, stream: dict) -> str | None:
    """``None`` when the baseline's stream description matches ``stream``, else the differences as text;
    ``"no stream description"`` when the baseline carries none (old file)."""
    if not base:
        return None
    diffs = []
    if base.get("units", "SI") != "SI":
        diffs.append(f"units {base.get('units')} (expected SI)")
    if base.get("message") and stream.get("message") and base["message"] != stream["message"]:
        diffs.append(f"message {base['message']} vs stream {stream['message']}")
    rb, rs = base.get("rate_hz"), stream.get("rate_hz")
    if rb and rs and abs(float(rb) / float(rs) - 1.0) > RATE_TOL:
        diffs.append(f"rate {float(rb):.4g} Hz vs stream {float(rs):.4g} Hz")
    lb, ls = base.get("gyro_lsb"), stream.get("gyro_lsb")
    if (lb is None) != (ls is None) or (lb and ls and abs(float(lb) / float(ls) - 1.0) > LSB_TOL):
        fmt = lambda v: "none (float)" if v is None else f"{float(v):.4g} rad/s"  # noqa: E731
        diffs.append(f"gyro LSB {fmt(lb)} vs stream {fmt(ls)}")
    return "; ".join(diffs) or None


def units_mismatch(base_params: dict | None, current: dict) -> str | None:
    """A white-noise density more than N_RATIO_MAX off the baseline's: another sensor or other units."""
    if not base_params or "N" not in base_params or "N" not in current:
        return None
    b, c = base_params["N"][0], current["N"][0]
    if not (b > 0 and c > 0 and math.isfinite(b) and math.isfinite(c)):
        return None
    r = c / b
    if r > N_RATIO_MAX or r < 1.0 / N_RATIO_MAX:
        return f"white noise N of the stream is {r:.3g}x the baseline's (another sensor, or not SI units)"
    return None


def check_baseline(baseline, ch, force: bool, log) -> str | None:
    """The one-line error when the loaded ``baseline`` does not match channel ``ch`` (None when it does);
    with ``force`` only log it."""
    text = mismatch(baseline.meta.get(ch.imu), stream_meta(ch))
    if text is None:
        if ch.imu not in baseline.meta:
            log(f"IMU{ch.imu}: baseline {baseline.source} has no stream description (rate, message, LSB): not checked")
        return None
    line = f"baseline {baseline.source} does not match IMU{ch.imu} ({ch.message}): {text}"
    if force:
        log(line + " (used anyway: --baseline-force)")
        return None
    return line + "; use a baseline of this stream or --baseline-force"
