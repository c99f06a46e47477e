"""What the live page of ``run --web`` shows, as one JSON-ready dict built in the pipeline's own thread
(:meth:`companion.service.evidence_log.EvidenceLog.publish_now`): per IMU its health, active faults, the
coefficients of the last check with their 95 % intervals (SI and the datasheet text), the Allan deviation of
its slow estimator with 95 % bands, the white noise N per condition (``conditions``: still, from the IMU
alone; armed on the ``ground`` and in ``flight``, from the differences with the other IMUs,
service/inflight_live.py) and the alarms with their evidence (key ``evidence``, served apart)."""

from __future__ import annotations

import math

import numpy as np

from companion.health.degradation import STATE_NAMES
from companion.samples import GYRO_AXES

PARAMS = ("N", "B", "K")


def _finite(v) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None


def adev_curve(est) -> dict | None:
    """The estimator's Allan deviation (rad/s) with a 95 % chi-square band from its EDF, or None."""
    from scipy.stats import chi2

    if est is None or not hasattr(est, "avar"):
        return None
    tau, avar, edf = est.avar()
    ok = np.isfinite(avar) & (avar > 0) & (edf > 0)
    if not ok.any():
        return None
    tau, avar, edf = tau[ok], avar[ok], edf[ok]
    lo = avar * edf / chi2.ppf(0.975, edf)
    hi = avar * edf / chi2.ppf(0.025, edf)
    return {"tau_s": [float(x) for x in tau], "adev": [float(x) for x in np.sqrt(avar)],
            "lo": [float(x) for x in np.sqrt(lo)], "hi": [float(x) for x in np.sqrt(hi)]}


def coefficient_rows(terms, axis: str) -> list[dict]:
    """N, B, K of one axis: SI value, 95 % interval (or bound) and the datasheet text of the summary."""
    from companion import units
    from companion.estimators.online_report import cell

    out = []
    for p in PARAMS:
        for t in terms or ():
            if p not in t or not isinstance(t.get(p), (int, float)):
                continue
            ci = (t.get("ci95") or {}).get(p)
            out.append({"param": p, "value": _finite(t[p]), "bound": bool(t.get("bound", False)),
                        "ci95": [_finite(ci[0]), _finite(ci[1])] if ci else None,
                        "text": cell(terms, p, axis), "unit": units.datasheet_unit(p, axis)})
            break
    return out


def _inflight_terms(n: float, s: float, bound: bool) -> list[dict]:
    """One in-flight figure (N, 1-sigma, bound) as the terms ``cell`` reads: a 95 % interval, or a bound."""
    lo, hi = max(n - 1.96 * s, 0.0), n + 1.96 * s
    return [{"N": n, "bound": bool(bound), "std": {"N": s}, "ci95": {"N": [lo, hi]}}]


def condition_rows(pipeline, imu: int) -> list[dict]:
    """Per condition (still, ground, flight) and axis the IMU's white noise N: its value, 95 % interval or
    bound (SI and the datasheet text) and where it comes from, or a note saying why there is none."""
    from companion import units
    from companion.estimators.online_report import cell
    from companion.service.inflight_live import CONDITIONS

    out = []
    terms = pipeline.evidence.terms.get(imu, {})
    for ax in GYRO_AXES:
        row = next((r for r in coefficient_rows(terms.get(ax), ax) if r["param"] == "N"), None)
        out.append(dict(row or {"value": None, "bound": False, "ci95": None, "text": "n/a"}, condition="still",
                        axis=ax, unit=units.datasheet_unit("N", ax),
                        source=("the IMU alone at rest (online Allan fit)" if row
                                else "no figure yet: no check at rest")))
    noise = pipeline.inflight.noise
    for cond in CONDITIONS:
        figs = noise.figures.get(cond) or {}
        who = imu if imu in figs else next((w for w in figs if isinstance(w, tuple) and imu in w), None)
        secs = max((p.seconds[cond] for k, p in noise.pairs.items() if imu in k), default=0.0)
        if len(pipeline.channels) < 2:
            why = "no figure: one IMU (its noise cannot be told from the motion)"
        elif who is None:
            none = "no data armed on the ground" if cond == "ground" else "no data armed and turning"
            why = "no figure yet: " + (none if secs == 0 else f"{secs:.0f} s of data, no noise level resolved yet")
        for ax in GYRO_AXES:
            fig = figs[who].get(ax) if who is not None else None
            if fig is None:
                out.append({"condition": cond, "axis": ax, "value": None, "bound": False, "ci95": None,
                            "text": "n/a", "unit": units.datasheet_unit("N", ax),
                            "source": why if who is None else "no figure yet on this axis"})
                continue
            n, sd, bound = fig
            pair = isinstance(who, tuple)
            t = _inflight_terms(n, sd, bound or pair)
            out.append({"condition": cond, "axis": ax, "value": _finite(n), "bound": bool(bound or pair),
                        "ci95": None if bound or pair else [_finite(x) for x in t[0]["ci95"]["N"]],
                        "text": cell(t, "N", ax), "unit": units.datasheet_unit("N", ax),
                        "source": (f"the pair IMU{who[0]}-IMU{who[1]}'s figure bounds each" if pair
                                   else "three-cornered hat of the IMU differences") + f"; {secs:.0f} s"})
    return out


def snapshot(pipeline) -> dict:
    """The live page's data (SI; message time in s)."""
    ev = pipeline.evidence
    imus = []
    for imu, ch in sorted(pipeline.channels.items()):
        terms = ev.terms.get(imu, {})
        axes = {}
        for ax in GYRO_AXES:
            est = (ch.slow or {}).get(ax) or (ch.learn or {}).get(ax)
            axes[ax] = {"coefficients": coefficient_rows(terms.get(ax), ax), "adev": adev_curve(est)}
        imus.append({"imu": imu, "message": ch.message, "rate_hz": ch.rate_hz, "t_s": ch.last_t,
                     "health": STATE_NAMES[pipeline.health(ch)], "faults": pipeline.fault_texts(ch),
                     "still_s": ch.fed_s, "axes": axes, "conditions": condition_rows(pipeline, imu)})
    items = ev.all_items()
    alarms = [{"index": i, "imu": it["imu"], "axis": it["axis"], "kind": it["kind"], "t_s": it["t_s"],
               "text": it["text"], "sentence": it["sentence"], "complete": it.get("complete", False)}
              for i, it in enumerate(items)]
    return {"kind": "live", "imus": imus, "alarms": alarms, "transitions": [[t, s] for t, s in pipeline.transitions[-50:]],
            "evidence": items}


def report_data(pipeline, source: str) -> dict:
    """What ``run --report`` writes: per IMU its health and active faults, every alarm with its evidence."""
    imus = [{"imu": imu, "message": ch.message, "rate_hz": ch.rate_hz, "health": STATE_NAMES[pipeline.health(ch)],
             "faults": pipeline.fault_texts(ch)} for imu, ch in sorted(pipeline.channels.items())]
    return {"source": str(source), "imus": imus, "alarms": pipeline.evidence.all_items(),
            "transitions": [[t, s] for t, s in pipeline.transitions]}
