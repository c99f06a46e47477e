"""The fleet report's interactive part and the evidence of its flagged IMUs, in the evidence schema of
``run`` (docs/reports.md): per flagged IMU the trended parameter of every gyro axis per flight with its 95 %
interval (SI; the interactive plots in datasheet units), the trend evidence (-log10 p) after each flight against the flag threshold, and one sentence. The
x axis is the flight's index in time order (``x_label``), not message time; there is no spectrum."""

from __future__ import annotations

import math

import numpy as np

from companion import units
from companion.fleet.trends import EVIDENCE_THRESHOLD, MIN_RISE, imu_trend

GYRO = ("gx", "gy", "gz")
SI_UNIT = {"N": "rad/s/sqrt(Hz)", "B": "rad/s", "K": "rad/s^1.5"}  # the evidence JSON is SI, as every JSON


def _label(e: dict) -> str:
    return f"{e['vehicle']} IMU{e['imu']} ({e['message']}, sysid {e['sysid']})"


def _nums(a) -> list:
    return [float(x) if math.isfinite(float(x)) else None for x in np.asarray(a, dtype=float)]


def trend_series(e: dict, param: str, si: bool = False) -> dict:
    """Per gyro axis the flight indices, values and 95 % intervals of ``param`` in datasheet units (``si``: SI)."""
    out = {}
    for ax in GYRO:
        s = e["_series"].get((ax, param))
        if s is None or not len(s[1]):
            continue
        idx, v, lo, hi = s
        f = 1.0 if si else units.to_datasheet(param, 1.0, ax)
        out[ax] = {"x": _nums(idx), "y": _nums(np.asarray(v) * f), "lo": _nums(np.asarray(lo) * f),
                   "hi": _nums(np.asarray(hi) * f)}
    return out


def evidence_after_each_flight(e: dict, threshold: float, min_rise: float) -> tuple[list, list]:
    """The trend test over the first k flights, k = 2 .. all: (k - 1 as flight index, evidence)."""
    xs, ev = [], []
    for k in range(2, e["flights"] + 1):
        sub = {key: tuple(np.asarray(a)[np.asarray(s[0]) < k] for a in s) for key, s in e["_series"].items()}
        tr = imu_trend(sub, k, threshold, min_rise)
        xs.append(float(k - 1))
        ev.append(float(tr.evidence) if math.isfinite(tr.evidence) else None)
    return xs, ev


def evidence_item(e: dict, threshold: float = EVIDENCE_THRESHOLD, min_rise: float = MIN_RISE) -> dict:
    """The evidence of one flagged IMU."""
    p, ax = e["param"], e["axis"]
    series = trend_series(e, p, si=True)
    xs, ev = evidence_after_each_flight(e, threshold, min_rise)
    unit = SI_UNIT[p]
    text = f"{e['vehicle']} IMU{e['imu']} gyro {ax[1].upper()} {p} rising {e['trend']:.2f}x over {e['flights']} flights"
    sentence = (f"{_label(e)}: {p} of axis {ax[1].upper()} rose {e['trend']:.2f}x from the first flight to the last "
                f"(weighted fit on the per-flight 95 % intervals); the evidence -log10(p) reached {e['evidence']:.1f}, "
                f"at or above the flag threshold {threshold:g}, with a rise of at least {min_rise:g}x.")
    return {"source": "fleet", "vehicle": e["vehicle"], "sysid": e["sysid"], "message": e["message"],
            "imu": e["imu"], "axis": ax, "kind": "trend", "t_s": None, "x_label": "flight (index in time order)",
            "text": text, "sentence": sentence, "value": e["trend"], "complete": True,
            "series": [{"imu": e["imu"], "role": "alarm", "label": _label(e), "quantity": f"{p} per flight, 95 % intervals",
                        "unit": unit, "t_s": series[a]["x"] if a in series else [], "y": {a: series[a]["y"]},
                        "lo": {a: series[a]["lo"]}, "hi": {a: series[a]["hi"]}} for a in GYRO if a in series],
            "statistic": {"name": "trend evidence -log10(p) over the flights so far", "unit": "-log10 p",
                          "t_s": xs, "value": ev, "threshold": [threshold] * len(xs),
                          "state": [int(v is not None and v >= threshold) for v in ev]},
            "spectrum": None}


def fleet_view(entries: list[dict], max_plots: int = 100) -> dict:
    """The data of the fleet report's interactive part (webview.pages.fleet_section)."""
    imus = []
    for e in entries[:max_plots]:
        p = e["param"] or "N"
        imus.append({"label": _label(e), "param": p, "unit": units.datasheet_unit(p, "gx"),
                     "series": trend_series(e, p)})
    return {"imus": imus, "evidence": fleet_evidence(entries)}


def fleet_evidence(entries: list[dict]) -> list[dict]:
    """The evidence items of the flagged IMUs (the fleet JSON's ``evidence`` list)."""
    return [evidence_item(e) for e in entries if e["flagged"] and e["axis"]]
