"""What the live page of ``run --web`` shows, as one JSON-ready dict built in the pipeline's own thread
(:meth:`companion.service.evidence_log.EvidenceLog.publish_now`): per IMU its health, active faults, the
coefficients of the last check with their 95 % intervals (SI and the datasheet text), the Allan deviation of
its slow estimator with 95 % bands, and the alarms with their evidence (key ``evidence``, served apart)."""

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
                     "still_s": ch.fed_s, "axes": axes})
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
