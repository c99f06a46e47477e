"""Fleet figure: one IMU's white noise N (or the worst parameter) per flight with 95 % intervals and
the fitted trend of each axis (datasheet units), as PNG bytes for the HTML report."""

from __future__ import annotations

import io

import numpy as np

from companion import units
from companion.plots import require_matplotlib

COLORS = {"gx": "tab:red", "gy": "tab:green", "gz": "tab:blue", "ax": "tab:orange", "ay": "tab:olive",
          "az": "tab:cyan"}


def imu_trend_png(entry: dict, series: dict, tests: dict, dpi: int = 80) -> bytes:
    """PNG of ``series[(axis, param)] = (flight_index, value, lo, hi)`` for N (and the worst parameter
    when it is not N); ``tests[(axis, param)]``: :class:`companion.fleet.trends.SlopeTest` lines."""
    plt = require_matplotlib()
    params = ["N"] + ([entry["param"]] if entry.get("param") not in (None, "N") else [])
    fig, axs = plt.subplots(1, len(params), figsize=(5.6 * len(params), 2.9), squeeze=False)
    flights = max(int(entry["flights"]), 1)
    span = max(flights - 1, 1)
    for ax, p in zip(axs[0], params):
        shown = False
        for (axis, param), (idx, v, lo, hi) in sorted(series.items()):
            if param != p:
                continue
            idx, v, lo, hi = (np.asarray(a, dtype=float) for a in (idx, v, lo, hi))
            ok = np.isfinite(v) & (v > 0)
            if not ok.any():
                continue
            conv = units.to_datasheet(p, 1.0, axis)
            y = v[ok] * conv
            lo_ = np.where(np.isfinite(lo[ok]), lo[ok], v[ok]) * conv
            hi_ = np.where(np.isfinite(hi[ok]), hi[ok], v[ok]) * conv
            c = COLORS.get(axis, "k")
            ax.errorbar(idx[ok], y, yerr=[np.maximum(y - lo_, 0), np.maximum(hi_ - y, 0)], fmt="o", ms=3,
                        color=c, lw=0.8, capsize=1.5, label=axis)
            t = tests.get((axis, param))
            if t is not None:
                xx = np.linspace(0, flights - 1, 50)
                ax.plot(xx, np.exp(t.intercept + t.slope * xx / span) * conv, color=c, lw=1.4,
                        ls="-" if (axis, param) == (entry.get("axis"), entry.get("param")) else ":")
            shown = True
        ax.set_xlabel("flight (oldest first)")
        ax.set_ylabel(f"{p} [{units.datasheet_unit(p, 'gx')}]")
        ax.grid(alpha=0.3)
        if shown:
            ax.legend(fontsize=7, loc="best")
    fig.suptitle(f"{entry['vehicle']} IMU{entry['imu']} ({entry['message']})"
                 + ("  FLAGGED" if entry.get("flagged") else ""), fontsize=10,
                 color="firebrick" if entry.get("flagged") else "black")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    plt.close(fig)
    return buf.getvalue()
