"""Gap figure: measured ADEV with its 95 % band, the old model (analytic and simulated), the new model,
and the tau ranges where the measurement left the old model's band shaded (red: measured above the model,
blue: below). Gyro in deg/h, accel in mg (the datasheet units of companion.units)."""

from __future__ import annotations

import numpy as np

from companion import units
from companion.gap.compare import model_avar
from companion.plots import require_matplotlib, save_figure


def plot_gap(result, path) -> None:
    """Write the figure of a :class:`companion.gap.gap_result.GapResult` to ``path`` (PNG, SVG, PDF...)."""
    plt = require_matplotlib()
    m = result.measured
    axis = result.axis
    f = units.to_datasheet("B", 1.0, axis)
    unit = units.datasheet_unit("B", axis)
    tau_fine = np.logspace(np.log10(m.tau[0]), np.log10(m.tau[-1]), 300)
    fig, ax = plt.subplots(figsize=(8, 5.5))
    for r in result.regions_before:
        lo, hi = r.tau_lo / 2**0.5, r.tau_hi * 2**0.5
        ax.axvspan(lo, hi, color="tab:red" if r.direction == "above" else "tab:blue", alpha=0.10, lw=0)
    ax.fill_between(m.tau, np.sqrt(m.lo) * f, np.sqrt(m.hi) * f, color="0.6", alpha=0.45, lw=0,
                    label="measured 95 % band")
    ax.loglog(m.tau, np.sqrt(m.avar) * f, "o", color="k", ms=4, label="measured")
    if result.terms_before:
        ax.loglog(tau_fine, np.sqrt(model_avar(result.terms_before, tau_fine, m.rate_hz)) * f, "--",
                  color="tab:red", label=f"model before (G = {result.gap_before:.3g})")
    if result.sim_avar_before is not None:
        ax.loglog(m.tau, np.sqrt(result.sim_avar_before) * f, "x", color="tab:red", ms=5,
                  label="model before, simulated")
    if result.terms_after is not result.terms_before:
        ax.loglog(tau_fine, np.sqrt(model_avar(result.terms_after, tau_fine, m.rate_hz)) * f, "-",
                  color="tab:green", lw=2, label=f"model after (G = {result.gap_after:.3g})")
        if result.sim_avar_after is not None:
            ax.loglog(m.tau, np.sqrt(result.sim_avar_after) * f, "+", color="tab:green", ms=7,
                      label="model after, simulated")
    added = ", ".join(a["effect"] if a.get("form") != "rate_lsb" else "rate quantisation" for a in result.added)
    ax.set_title(f"{axis}: gap {result.gap_before:.3g} -> {result.gap_after:.3g}"
                 + (f"; added {added}" if added else "; nothing added"), fontsize=10)
    ax.set_xlabel("cluster time tau (s)")
    ax.set_ylabel(f"Allan deviation ({unit})")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    save_figure(fig, path, plt)
