"""Kalibr imu.yaml from an analysis report, and why it would be wrong."""

from __future__ import annotations

import math
from typing import NamedTuple

from companion.samples import ACCEL_AXES, GYRO_AXES


def kalibr_yaml(report: dict) -> str:
    """Kalibr imu.yaml from the longest IMU stream: N and K of each sensor (continuous-time SI densities, as the
    report holds them: N in rad/s/sqrt(Hz) = rad/sqrt(s), K in rad/s^2/sqrt(Hz) = rad/s/sqrt(s); m/s in place of rad
    for the accelerometer).

    K of an axis is the analysis' own (:func:`axis_random_walk`): the fitted K, or its 95 % upper bound where the
    fit did not resolve it (said in a comment). Kalibr takes one value per sensor: the largest over its three axes,
    so that no axis' noise is under-modelled (a filter fed too little noise trusts its IMU too much).
    """
    st = max(report["streams"], key=lambda s: s["samples"])
    out = {}
    notes = []
    for sensor, axes in (("gyroscope", GYRO_AXES), ("accelerometer", ACCEL_AXES)):
        Ns, Ks = [], []
        for a in axes:
            r = st["axes"].get(a)
            if not r or r["status"] != "ok":
                continue
            terms = {t["effect"]: t for t in r["terms"]}
            if "white_noise" in terms:
                Ns.append(terms["white_noise"]["N"])
            k = axis_random_walk(r)
            if k is not None:
                Ks.append((k.value, a, k.note))
        out[f"{sensor}_noise_density"] = max(Ns) if Ns else 0.0
        out[f"{sensor}_random_walk"] = 0.0
        if Ks:
            value, axis, note = max(Ks, key=lambda k: k[0])
            out[f"{sensor}_random_walk"] = value
            notes.append(f"{sensor}_random_walk from {axis}: {note or 'its fitted K'}")
        if not Ns:
            notes.append(f"{sensor}: no usable axis; values 0")
    lines = ["# Kalibr IMU noise model written by `companion analyze` (continuous-time, SI):",
             "#   *_noise_density = N [rad/s/sqrt(Hz), m/s^2/sqrt(Hz)], *_random_walk = K [rad/s^2/sqrt(Hz), m/s^3/sqrt(Hz)]",
             f"#   stream {st['message']}[{st['instance']}] sys{st['sysid']}, largest value over the axes"]
    lines += [f"# note: {n}" for n in notes]
    lines.append("rostopic: /imu0")
    lines.append(f"update_rate: {st['rate_hz']:.6g}")
    for k in ("accelerometer_noise_density", "accelerometer_random_walk", "gyroscope_noise_density",
              "gyroscope_random_walk"):
        lines.append(f"{k}: {out[k]:.6e}")
    return "\n".join(lines) + "\n"


class AxisRandomWalk(NamedTuple):
    """K of one axis for the Kalibr file (SI), and why it is a bound (None: the fitted K)."""

    value: float
    note: str | None


def axis_random_walk(entry: dict) -> AxisRandomWalk | None:
    """K of one analysed axis (its report entry): the fitted K; else the analysis' 95 % upper bound of K;
    else, where neither exists, the bound sqrt(3 AVAR(tau_max) / tau_max) of the last point (a rate random walk
    alone would make AVAR(tau) = K^2 tau / 3 there); None without any point."""
    for t in entry.get("terms", []):
        if t["effect"] == "random_walk":
            return AxisRandomWalk(float(t["K"]), None)
    for b in entry.get("bounds", []):
        if b["effect"] == "random_walk":
            return AxisRandomWalk(float(b["K"]), "K not resolved by the fit: its 95 % upper bound")
    if entry.get("tau"):
        return AxisRandomWalk(math.sqrt(3.0 * entry["adev"][-1] ** 2 / entry["tau"][-1]),
                              "no random-walk region in the record and no bound from the fit: "
                              "the upper bound sqrt(3 AVAR(tau_max) / tau_max)")
    return None


def kalibr_blockers(report: dict) -> list[str]:
    """Why a Kalibr file would be wrong (warnings of the stream it would be written from)."""
    if not report["streams"]:
        return ["no stream analysed"]
    if not any(s.get("axes") for s in report["streams"]):  # a log armed throughout: ground and flight only
        return ["no still data (Kalibr's noise model is the still noise; the in-flight figures include vibration)"]
    st = max(report["streams"], key=lambda s: s["samples"])
    out = [f"{st['message']}[{st['instance']}]: {w}" for w in st.get("warnings", [])]
    for sensor, axes in (("gyroscope", GYRO_AXES), ("accelerometer", ACCEL_AXES)):
        # a 0 noise density tells Kalibr the sensor is perfect: never written without a word
        if not any(t["effect"] == "white_noise" for a in axes for t in (st["axes"].get(a) or {}).get("terms", [])
                   if (st["axes"].get(a) or {}).get("status") == "ok"):
            asked = [a for a in axes if a in st["axes"]]
            why = "no white-noise N resolved on " + ", ".join(asked) if asked else f"{','.join(axes)} not in --axes"
            out.append(f"{sensor}: {why} (its noise density would be written as 0)")
    return out
