"""Figure of ``companion compensate``, laid out like Shi et al.'s Figures 1 and 2.

Left column (Fig. 1 (a)-(c)): the raw series and the compensated series of each method against time.
Right (Fig. 2): overlapping Allan deviation of the raw data and of each compensated series.
matplotlib is imported lazily (optional extra ``plot``).
"""

from __future__ import annotations

import numpy as np

from companion.plots import require_matplotlib, save_figure

COLORS = {"stf": "tab:orange", "srukf": "tab:green", "srrsukf": "tab:red"}


def plot_compensation(result, t: np.ndarray, z: np.ndarray, path, title: str = "", unit_scale: float = 180.0 / np.pi,
                      unit: str = "deg/s", max_points: int = 20_000, max_tau: float = np.inf) -> None:
    """Write the figure for a :class:`companion.compensation.compare_methods.CompensationResult` to ``path``.

    ``t`` and ``z`` are the time (s) and raw series (SI); values are shown times ``unit_scale`` in ``unit``.
    Time series are decimated to at most ``max_points`` points for drawing (the ADEV uses every sample).
    Allan deviations are drawn up to ``max_tau`` (s).
    """
    plt = require_matplotlib()

    methods = list(result.methods.values())
    rows = max(len(methods), 1)
    fig = plt.figure(figsize=(13, 2.6 * rows + 1.0))
    grid = fig.add_gridspec(rows, 2, width_ratios=[1.4, 1.0])
    step = max(1, int(np.ceil(len(z) / max_points)))
    ts = t[::step] - t[0]
    for i, m in enumerate(methods):
        ax = fig.add_subplot(grid[i, 0])
        ax.plot(ts, z[::step] * unit_scale, color="0.6", lw=0.5, label="raw")
        ax.plot(ts, m.x[::step] * unit_scale, color=COLORS.get(m.name, "C0"), lw=0.8, label=m.label)
        ax.set_ylabel(unit)
        ax.set_title(f"({chr(97 + i)}) raw and compensated: {m.label}", fontsize=9, loc="left")
        ax.legend(loc="upper right", fontsize=8)
        ax.grid(alpha=0.3)
        if i == rows - 1:
            ax.set_xlabel("time (s)")
    ax = fig.add_subplot(grid[:, 1])
    keep = result.raw_tau <= max_tau
    ax.loglog(result.raw_tau[keep], result.raw_adev[keep] * unit_scale, "o-", color="0.3", ms=3, label="raw")
    for m in methods:
        k = m.tau <= max_tau
        ax.loglog(m.tau[k], m.adev[k] * unit_scale, "o-", ms=3, color=COLORS.get(m.name, "C0"), label=m.label)
    ax.set_xlabel("tau (s)")
    ax.set_ylabel(f"Allan deviation ({unit})")
    ax.set_title("Allan deviation of raw and compensated data", fontsize=9, loc="left")
    ax.grid(which="both", alpha=0.3)
    ax.legend(fontsize=8)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    save_figure(fig, path, plt)
