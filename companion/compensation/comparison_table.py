"""What ``compensate`` shows of a :class:`companion.compensation.compare_methods.CompensationResult`: the ADEV ratio
table at a few cluster times, the warning when no method helped, the JSON report and the CSV of the series.

The table stops at T/10 of the record (:func:`max_tau`): beyond it the overlapping Allan estimate rests on
fewer than ten clusters.
"""

from __future__ import annotations

import numpy as np

from companion.errors import CompanionError
from companion.units import rate_display

#: The table stops at T/10: beyond it the overlapping Allan estimate rests on fewer than ten clusters.
MAX_TAU_FRACTION = 0.1

#: A method "helped" when it brought the ADEV at tau0 below this fraction of the raw ADEV.
HELPED_RATIO = 0.9

#: Cluster times the table aims at (s), besides tau0: white noise at 1 s, bias instability near 100 s.
TABLE_TAUS_S = (1.0, 100.0)


def max_tau(n: int, rate_hz: float) -> float:
    """The longest cluster time shown (table and plot) for ``n`` samples at ``rate_hz``: T/10."""
    return MAX_TAU_FRACTION * n / rate_hz + 1e-12


def _samples(result) -> int:
    return len(next(iter(result.methods.values())).x)


def table_taus(result) -> list[int]:
    """Indices of the taus shown: tau0, about 1 s and about 100 s, none beyond T/10 of the record."""
    tau = result.raw_tau
    ok = np.flatnonzero(tau <= max_tau(_samples(result), result.rate_hz))
    if ok.size == 0:
        return [0]
    return sorted({int(ok[np.argmin(np.abs(np.log(tau[ok]) - np.log(v)))]) for v in (tau[0], *TABLE_TAUS_S)})


def format_table(result, axis: str, label: str) -> str:
    """The fitted model line, then per method its ADEV ratio to raw at :func:`table_taus`, speed and whether
    its covariance factor stayed valid."""
    tau = result.raw_tau
    scale, unit = rate_display(axis)
    p = result.params
    picks = table_taus(result)
    lines = [f"{label} {axis}: {_samples(result)} samples at {result.rate_hz:g} Hz; "
             f"ARIMA(1,1,1) fit ({p.split}): phi={p.phi:.4f} theta={p.theta:.4f} "
             f"delta1={p.delta1 * p.scale * scale:.3g} {unit} sqrt(R)={np.sqrt(p.R) * p.scale * scale:.3g} {unit}"]
    head = f"{'method':<20}" + "".join(f"{'ADEV ratio @' + format(tau[i], '.3g') + ' s':>20}" for i in picks)
    lines.append(head + f"{'samples/s':>12}{'factor ok':>11}")
    lines.append(f"{'raw ADEV (' + unit + ')':<20}" + "".join(f"{result.raw_adev[i] * scale:>20.4g}" for i in picks))
    for m in result.methods.values():
        ratio = m.adev / result.raw_adev
        lines.append(f"{m.label:<20}" + "".join(f"{ratio[i]:>20.3f}" for i in picks)
                     + f"{m.samples_per_s:>12.0f}{'yes' if m.factor_valid else 'NO':>11}")
    return "\n".join(lines)


def nothing_helped(result) -> str | None:
    """A warning when no method brought the ADEV at tau0 below ``HELPED_RATIO`` x raw, else None."""
    ratios = {m.label: float(m.adev[0] / result.raw_adev[0]) for m in result.methods.values()}
    if not ratios or min(ratios.values()) < HELPED_RATIO:
        return None
    best = min(ratios, key=ratios.get)
    return (f"no method brought the ADEV at tau0 ({result.raw_tau[0]:.3g} s) below {HELPED_RATIO:g}x raw (best: "
            f"{best} {ratios[best]:.3f}x): little white noise found to remove (motion, or noise the model "
            f"does not describe)")


def json_report(result, axis: str, label: str) -> dict:
    """``compensate --json``: the result's JSON (SI units) and the stream it came from."""
    report = result.to_json(axis)
    report["stream"] = label
    return report


def write_series_csv(path, t, z, result, axis: str) -> None:
    """``compensate --out``: time_s, the raw series and one column per method (the input's unit)."""
    cols = [t, z] + [m.x for m in result.methods.values()]
    header = ",".join(["time_s", f"{axis}_raw"] + [f"{axis}_{name}" for name in result.methods])
    try:
        np.savetxt(path, np.column_stack(cols), delimiter=",", header=header, comments="", fmt="%.9g")
    except OSError as exc:
        raise CompanionError(f"{path}: cannot write CSV ({exc.strerror or exc})") from None
