"""Allan deviation figure for a report: measured ADEV with its 95 % band, each fitted term and their sum.

Gyro panels in deg/h, accel panels in mg (ADEV of the rate), against the cluster time in seconds; the
legend gives each fitted coefficient in datasheet units with its 95 % interval.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from companion import units
from companion.allan.terms import PARAMS, avar_term
from companion.plots import require_matplotlib, save_figure
from companion.samples import ACCEL_AXES, GYRO_AXES

_LABEL = {"white_noise": "white noise", "bias_instability": "bias instability", "random_walk": "rate random walk",
          "quantization": "quantization", "ramp": "rate ramp", "gauss_markov": "Gauss-Markov",
          "sinusoid": "sinusoid"}
_COLORS = {"quantization": "tab:purple", "white_noise": "tab:blue", "bias_instability": "tab:green",
           "random_walk": "tab:red", "ramp": "tab:brown", "gauss_markov": "tab:orange", "sinusoid": "tab:pink"}


def _value_text(t, axis):
    parts = []
    for p in PARAMS[t["effect"]]:
        v = units.to_datasheet(p, t[p], axis)
        ci = t.get("ci95", {}).get(p)
        s = f"{p}={v:.3g}"
        if ci:
            s += f" [{units.to_datasheet(p, ci[0], axis):.3g}, {units.to_datasheet(p, ci[1], axis):.3g}]"
        parts.append(s + " " + units.datasheet_unit(p, axis))
    if t["effect"] == "white_noise" and t.get("filter_hz"):
        # the dashed white-noise line bends below the filter's corner: say which filter
        parts.append(f"through a {int(t.get('filter_order') or 2)}-pole {t['filter_hz']:.3g} Hz low-pass")
    return ", ".join(parts)


def draw_axis(ax, axis: str, r: dict) -> None:
    """Draw one axis result (the JSON ``axes`` entry) on matplotlib axes ``ax``."""
    gyro = axis in GYRO_AXES
    f = units.to_datasheet("B", 1.0, axis)  # rad/s -> deg/h, m/s^2 -> mg
    unit = "deg/h" if gyro else "mg"
    ax.set_title(axis + (" (gyro)" if gyro else " (accel)"), fontsize=10)
    if r.get("status") != "ok" or not r.get("tau"):
        ax.text(0.5, 0.5, f"{r.get('status')}\n{r.get('note', '')}", ha="center", va="center",
                transform=ax.transAxes, fontsize=9, wrap=True)
        ax.set_xticks([])
        ax.set_yticks([])
        return
    tau = np.asarray(r["tau"])
    adev = np.asarray(r["adev"]) * f
    ax.fill_between(tau, np.asarray(r["adev_lo"]) * f, np.asarray(r["adev_hi"]) * f, color="0.8",
                    label="95 % interval", linewidth=0)
    ax.loglog(tau, adev, "o", ms=3.5, color="k", label="overlapping ADEV")
    if r["terms"]:
        tt = np.logspace(np.log10(tau[0]), np.log10(tau[-1]), 200)
        total = np.zeros_like(tt)
        for t in r["terms"]:
            plain = {k: v for k, v in t.items() if k != "ci95"}
            av = avar_term(plain, tt)
            total += av
            ax.loglog(tt, np.sqrt(av) * f, "--", lw=1.2, color=_COLORS.get(t["effect"]),
                      label=f"{_LABEL[t['effect']]}: {_value_text(t, axis)}")
        for t in r.get("unresolved") or []:
            av = avar_term(t, tt)
            total += av
            ax.loglog(tt, np.sqrt(av) * f, ":", lw=1.2, color=_COLORS.get(t["effect"]),
                      label=f"{_LABEL[t['effect']]}: not resolved by the record, kept in the model")
        nb = next((t for t in r.get("bounds") or [] if t["effect"] == "white_noise"), None)
        if nb is not None:
            # N not resolved: its bound is the least filter-corrected AVAR x tau (with its one-sided margin), so
            # the line reaches the data there and lies below them elsewhere; without it the sum below would miss
            # the short-tau points with nothing on the figure saying why
            ax.loglog(tt, np.sqrt(avar_term(nb, tt)) * f, "-.", lw=1.2, color=_COLORS["white_noise"],
                      label=f"white noise not resolved: N < {units.to_datasheet('N', nb['N'], axis):.3g} "
                            f"{units.datasheet_unit('N', axis)} (a bound, not in the sum)")
        ax.loglog(tt, np.sqrt(total) * f, "-", lw=1.6, color="tab:cyan",
                  label="sum of fitted terms" + (" (without N)" if nb is not None else ""))
        lo_v, hi_v = np.asarray(r["adev_lo"]) * f, np.asarray(r["adev_hi"]) * f
        lo_v, hi_v = lo_v[np.isfinite(lo_v) & (lo_v > 0)], hi_v[np.isfinite(hi_v)]
        if lo_v.size and hi_v.size:
            ax.set_ylim(lo_v.min() / 2.0, min(hi_v.max(), 30.0 * adev.max()) * 2.0)
    q = r.get("quantization")
    if q:
        ax.loglog(tau, q["N_q"] / np.sqrt(tau) * f, color="0.5", lw=0.9, ls=":",
                  label=f"1-LSB rounding, N_q={units.to_datasheet('N', q['N_q'], axis):.3g} "
                        f"{units.datasheet_unit('N', axis)} ({'dithered' if q['dithered'] else 'NOT dithered'})")
    ax.set_xlabel("cluster time tau [s]")
    ax.set_ylabel(f"Allan deviation [{unit}]")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=6.5, loc="best", framealpha=0.85)


def plot_stream(stream: dict, path, title: str | None = None) -> None:
    plt = require_matplotlib()
    rows = [[a for a in names if a in stream["axes"]] for names in (GYRO_AXES, ACCEL_AXES)]
    rows = [r for r in rows if r]
    ncol = max(len(r) for r in rows)
    fig, axs = plt.subplots(len(rows), ncol, figsize=(5.2 * ncol, 4.4 * len(rows)), squeeze=False)
    for i, row in enumerate(rows):
        for j in range(ncol):
            if j < len(row):
                draw_axis(axs[i][j], row[j], stream["axes"][row[j]])
            else:
                axs[i][j].set_visible(False)
    fig.suptitle(title or (f"{stream['message']}[{stream['instance']}] sys{stream['sysid']}/comp{stream['compid']}: "
                           f"{stream['samples']} samples at {stream['rate_hz']:.4g} Hz ({stream['duration_s']:.0f} s)"),
                 fontsize=11)
    fig.tight_layout()
    save_figure(fig, path, plt)


def _stream_label(st: dict, several_sources: bool) -> str:
    lab = f"{st['message']}[{st['instance']}]"
    if several_sources and st.get("source"):
        lab = f"{Path(st['source']).name} {lab}"
    return lab


def plot_overlay(report: dict, path) -> None:
    """Every stream of the report (every IMU of a log, and of several logs) in one figure: a panel per axis,
    each stream's measured ADEV (points and 95 % band) and its fitted model (line), legend with N."""
    plt = require_matplotlib()
    streams = [st for st in report["streams"] if any(r.get("status") == "ok" for r in st["axes"].values())]
    several = len({st.get("source") for st in streams}) > 1
    rows = [[a for a in names if any(a in st["axes"] and st["axes"][a].get("status") == "ok" for st in streams)]
            for names in (GYRO_AXES, ACCEL_AXES)]
    rows = [r for r in rows if r]
    if not rows:
        return
    ncol = max(len(r) for r in rows)
    fig, axs = plt.subplots(len(rows), ncol, figsize=(5.4 * ncol, 4.6 * len(rows)), squeeze=False)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for i, row in enumerate(rows):
        for j in range(ncol):
            ax = axs[i][j]
            if j >= len(row):
                ax.set_visible(False)
                continue
            axis = row[j]
            gyro = axis in GYRO_AXES
            f = units.to_datasheet("B", 1.0, axis)
            for k, st in enumerate(streams):
                r = st["axes"].get(axis)
                if not r or r.get("status") != "ok" or not r.get("tau"):
                    continue
                c = colors[k % len(colors)]
                tau = np.asarray(r["tau"])
                ax.fill_between(tau, np.asarray(r["adev_lo"]) * f, np.asarray(r["adev_hi"]) * f, color=c,
                                alpha=0.15, linewidth=0)
                nterm = next((t for t in r["terms"] if t["effect"] == "white_noise"), None)
                ntext = (f", N={units.to_datasheet('N', nterm['N'], axis):.3g} {units.datasheet_unit('N', axis)}"
                         if nterm else "")
                ax.loglog(tau, np.asarray(r["adev"]) * f, "o", ms=3, color=c,
                          label=_stream_label(st, several) + ntext)
                if r["terms"]:
                    tt = np.logspace(np.log10(tau[0]), np.log10(tau[-1]), 120)
                    tot = sum(avar_term({kk: v for kk, v in t.items() if kk != "ci95"}, tt) for t in r["terms"])
                    ax.loglog(tt, np.sqrt(tot) * f, "-", lw=1.1, color=c)
            ax.set_title(axis + (" (gyro)" if gyro else " (accel)"), fontsize=10)
            ax.set_xlabel("cluster time tau [s]")
            ax.set_ylabel(f"Allan deviation [{'deg/h' if gyro else 'mg'}]")
            ax.grid(True, which="both", alpha=0.3)
            ax.legend(fontsize=6.5, loc="best", framealpha=0.85)
    srcs = sorted({Path(st.get("source") or report.get("source", "")).name for st in streams})
    fig.suptitle(f"Allan deviation, {len(streams)} streams of {', '.join(srcs)} (points: measured with 95 % band; "
                 "lines: fitted model)", fontsize=10)
    fig.tight_layout()
    save_figure(fig, path, plt)


def plot_report(report: dict, path) -> list[str]:
    """A single stream: one PNG at ``path``. Several streams (the IMUs of a log, or several logs): ``path``
    overlays them all (:func:`plot_overlay`) and each stream also gets its own detailed figure
    ``<stem>_<message><instance>_sys<id><suffix>`` (with the source's name when there are several)."""
    streams = report["streams"]
    p = Path(path)
    out = []
    several = len({st.get("source") for st in streams}) > 1
    if len(streams) > 1:
        plot_overlay(report, p)
        out.append(str(p))
    for st in streams:
        src = f"{Path(st['source']).name.split('.')[0]}_" if several and st.get("source") else ""
        target = p if len(streams) == 1 else p.with_name(
            f"{p.stem}_{src}{st['message']}{st['instance']}_sys{st['sysid']}{p.suffix or '.png'}")
        plot_stream(st, target)
        out.append(str(target))
    return out
