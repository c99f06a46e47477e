"""Kalibr imu.yaml from an analysis report, and why it would be wrong."""

from __future__ import annotations

import math

from companion.samples import ACCEL_AXES, GYRO_AXES


def kalibr_yaml(report: dict) -> str:
    """Kalibr imu.yaml from the longest IMU stream: the largest N and K over the three axes of each sensor.

    A K not found by the fit (no random-walk region within the record) is replaced by the upper bound
    sqrt(3 AVAR(tau_max) / tau_max) and said so in a comment.
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
            if "random_walk" in terms:
                Ks.append(terms["random_walk"]["K"])
            elif r["tau"]:
                Ks.append(math.sqrt(3.0 * r["adev"][-1] ** 2 / r["tau"][-1]))
                notes.append(f"{a}: no random-walk region in the record; {sensor}_random_walk is an upper bound")
        out[f"{sensor}_noise_density"] = max(Ns) if Ns else 0.0
        out[f"{sensor}_random_walk"] = max(Ks) if Ks else 0.0
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


def kalibr_blockers(report: dict) -> list[str]:
    """Why a Kalibr file would be wrong (warnings of the stream it would be written from)."""
    if not report["streams"]:
        return ["no stream analysed"]
    st = max(report["streams"], key=lambda s: s["samples"])
    return [f"{st['message']}[{st['instance']}]: {w}" for w in st.get("warnings", [])]
