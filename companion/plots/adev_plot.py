"""Allan deviation figure for a report: measured ADEV with its 95 % band, each fitted term and their sum.

Gyro panels in deg/h, accel panels in mg (ADEV of the rate), against the cluster time in seconds; the
legend gives each fitted coefficient in datasheet units with its 95 % interval. Every legend sits in its own
strip below its panel, never on the data: the short-tau points, where N is read, are where a legend inside the
axes would land. Where the fit declared a model misfit the legend says so with the report's own record of it
(:func:`misfit_text`): the model error, the local white-noise refit's region (shaded) that N comes from, and how
far the drawn model lies from the points at shorter cluster times.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np

from companion import units
from companion.allan.terms import avar_term
from companion.analysis.report_table import term_parts
from companion.plots import require_matplotlib, save_figure
from companion.samples import ACCEL_AXES, GYRO_AXES

_LABEL = {"white_noise": "white noise", "bias_instability": "bias instability", "random_walk": "rate random walk",
          "quantization": "quantization", "ramp": "rate ramp", "gauss_markov": "Gauss-Markov",
          "sinusoid": "sinusoid"}
_COLORS = {"quantization": "tab:purple", "white_noise": "tab:blue", "bias_instability": "tab:green",
           "random_walk": "tab:red", "ramp": "tab:brown", "gauss_markov": "tab:orange", "sinusoid": "tab:pink"}

#: legend text size [pt] and the characters per line a label is wrapped at (a 5.2-inch panel holds about 80)
LEGEND_FONT = 7.0
_WRAP = 78  #: characters per legend line (see LEGEND_FONT)


def _value_text(t, axis):
    parts = term_parts(t, axis, sep="=")  # the table's digits, so that figure and text read alike
    if t["effect"] == "white_noise" and t.get("filter_hz"):
        # the dashed white-noise line bends below the filter's corner: say which filter
        parts.append(f"through a {int(t.get('filter_order') or 2)}-pole {t['filter_hz']:.3g} Hz low-pass")
    return ", ".join(parts)


def _axis_kind(axis: str) -> str:
    return "gyro" if axis in GYRO_AXES else "accel"


def _model_avar(r: dict, tt) -> np.ndarray:
    """AVAR of the model the figure draws: the fitted terms and the unresolved ones the fit kept."""
    total = np.zeros_like(np.asarray(tt, dtype=float))
    for t in list(r.get("terms") or []) + list(r.get("unresolved") or []):
        total = total + avar_term({k: v for k, v in t.items() if k != "ci95"}, tt)
    return total


def misfit_text(r: dict, axis: str) -> str | None:
    """What the figure says where the fit declared a model misfit, from the report's own record of it
    (``fit.model_error``, ``fit.white_refit``), in the text table's words: the model error, which N is reported
    (the local white-noise refit's region and the global fit's N beside it), and how far the drawn model lies
    from the measured points at the cluster times shorter than that region. None without a misfit."""
    fit = r.get("fit") or {}
    me = fit.get("model_error") or 0.0
    if not me:
        return None
    text = f"model misfit: +{100 * me:.0f} % model error"
    ref = fit.get("white_refit")
    wn = next((t for t in r.get("terms") or [] if t["effect"] == "white_noise"), None)
    if not ref or wn is None:
        return text + " (the line is the fitted model; N from the global fit)"
    lo, hi = ref["tau"]
    how = "the flat white region" if ref.get("rule") == "flat" else "a local refit of"
    text += (f"; N from {how} {lo:.3g}-{hi:.3g} s (shaded), the global fit gave "
             f"{100 * (ref['N_global'] / ref['N'] - 1):+.1f} %")
    tau, adev = np.asarray(r["tau"], dtype=float), np.asarray(r["adev"], dtype=float)
    short = (tau < lo * (1 - 1e-9)) & np.isfinite(adev) & (adev > 0)
    if short.any():
        # the line drawn against the points it is drawn over: the global fit's terms with the local N need not
        # pass the shortest cluster times, which the refit leaves out
        dev = np.sqrt(_model_avar(r, tau[short])) / adev[short] - 1.0
        k = int(np.argmax(np.abs(dev)))
        text += (f"; below {lo:.3g} s the line lies up to {100 * abs(dev[k]):.0f} % "
                 f"{'below' if dev[k] < 0 else 'above'} the points")
    return text


def _wrap(label: str) -> str:
    if len(label) <= _WRAP:
        return label
    return "\n".join(textwrap.wrap(label, _WRAP, subsequent_indent="  ", break_on_hyphens=False))


def _legend_below(lax, handles, labels) -> None:
    """The panel's legend in its own strip ``lax`` (no data, no axis lines) below the panel."""
    lax.axis("off")
    if handles:
        lax.legend(handles, [_wrap(s) for s in labels], loc="upper center", fontsize=LEGEND_FONT,
                   frameon=False, borderaxespad=0.0, handlelength=2.2)


def _legend_height_in(labels: list[str]) -> float:
    """Height [in] a legend of ``labels`` takes (each line 1.25 font sizes, 0.5 between entries, a margin)."""
    if not labels:
        return 0.1
    lines = sum(_wrap(s).count("\n") + 1 for s in labels)
    return (1.25 * lines + 0.55 * len(labels) + 1.5) * LEGEND_FONT / 72.0


def _grid(plt, rows: list[list[str]], ncol: int, width: float, height: float):
    """A figure with a panel per axis and a legend strip below each row of panels: returns (fig, grid, panels,
    strips), panels and strips as lists of rows; cells past a row's end are hidden. :func:`_fit_strips` sizes
    the strips once the legends are known."""
    fig = plt.figure(figsize=(width * ncol, (height + 1.0) * len(rows) + 0.5), layout="constrained")
    gs = fig.add_gridspec(2 * len(rows), ncol)
    panels, strips = [], []
    for i, row in enumerate(rows):
        prow, srow = [], []
        for j in range(ncol):
            ax, lax = fig.add_subplot(gs[2 * i, j]), fig.add_subplot(gs[2 * i + 1, j])
            if j >= len(row):
                ax.set_visible(False)
                lax.set_visible(False)
            prow.append(ax)
            srow.append(lax)
        panels.append(prow)
        strips.append(srow)
    return fig, gs, panels, strips


def _fit_strips(fig, gs, height: float, labels_by_row: list[list[list[str]]]) -> None:
    """Each row's legend strip as tall as its longest legend, the figure as tall as panels (``height`` inches)
    and strips."""
    strips = [max((_legend_height_in(lab) for lab in row), default=0.1) for row in labels_by_row]
    ratios = [x for h in strips for x in (height, h)]
    gs.set_height_ratios(ratios)
    fig.set_size_inches(fig.get_size_inches()[0], sum(ratios) + 0.5)


def _suptitle(fig, text: str, size: float) -> None:
    """The figure's title, wrapped to its width (a one-panel figure is 5 inches wide: a log's name and the
    stream's description in one line ran off both edges)."""
    chars = max(int(fig.get_size_inches()[0] * 72.0 / (0.55 * size)), 30)
    fig.suptitle("\n".join(textwrap.wrap(text, chars, break_on_hyphens=False)), fontsize=size)


def _ylim(ax, r_list, f) -> None:
    """Y range from the measured bands, the band's top at most 30x the largest point: a 1-dof band at the
    longest cluster time reaches decades above the data and would squash every curve into a strip."""
    lo_v, hi_v, top = [], [], []
    for r in r_list:
        lo = np.asarray(r["adev_lo"], dtype=float) * f
        hi = np.asarray(r["adev_hi"], dtype=float) * f
        lo_v.append(lo[np.isfinite(lo) & (lo > 0)])
        hi_v.append(hi[np.isfinite(hi)])
        top.append(np.nanmax(np.asarray(r["adev"], dtype=float) * f))
    lo_v, hi_v = np.concatenate(lo_v), np.concatenate(hi_v)
    if lo_v.size and hi_v.size:
        ax.set_ylim(lo_v.min() / 2.0, min(hi_v.max(), 30.0 * max(top)) * 2.0)


def _label_axes(ax, axis: str) -> None:
    ax.set_xlabel("cluster time tau [s]")
    ax.set_ylabel(f"Allan deviation [{'deg/h' if axis in GYRO_AXES else 'mg'}]")
    ax.grid(True, which="both", alpha=0.3)


def draw_axis(ax, axis: str, r: dict, legend_ax=None, name: str = "") -> tuple[list, list]:
    """Draw one axis result (the JSON ``axes`` entry) on matplotlib axes ``ax``; ``name`` (the IMU) goes into the
    title. The legend goes into ``legend_ax`` (a strip below the panel) when given; returns its (handles,
    labels) either way, and puts no legend on ``ax``."""
    f = units.to_datasheet("B", 1.0, axis)  # rad/s -> deg/h, m/s^2 -> mg
    ax.set_title(f"{name + ' ' if name else ''}{axis} ({_axis_kind(axis)})", fontsize=10)
    if r.get("status") != "ok" or not r.get("tau"):
        ax.text(0.5, 0.5, f"{r.get('status')}\n{r.get('note', '')}", ha="center", va="center",
                transform=ax.transAxes, fontsize=9, wrap=True)
        ax.set_xticks([])
        ax.set_yticks([])
        if legend_ax is not None:
            _legend_below(legend_ax, [], [])
        return [], []
    tau = np.asarray(r["tau"])
    adev = np.asarray(r["adev"]) * f
    ax.fill_between(tau, np.asarray(r["adev_lo"]) * f, np.asarray(r["adev_hi"]) * f, color="0.8",
                    label="95 % interval of the measured ADEV", linewidth=0)
    ax.loglog(tau, adev, "o", ms=3.5, color="k", label="overlapping ADEV (measured)", zorder=3)
    ref = (r.get("fit") or {}).get("white_refit")
    note = misfit_text(r, axis)
    if ref and any(t["effect"] == "white_noise" for t in r.get("terms") or []):
        ax.axvspan(ref["tau"][0], ref["tau"][1], color=_COLORS["white_noise"], alpha=0.12, lw=0, label=note)
    elif note:
        ax.plot([], [], ls="none", label=note)  # a legend line without a mark
    if r["terms"]:
        tt = np.logspace(np.log10(tau[0]), np.log10(tau[-1]), 200)
        for t in r["terms"]:
            plain = {k: v for k, v in t.items() if k != "ci95"}
            ax.loglog(tt, np.sqrt(avar_term(plain, tt)) * f, "--", lw=1.2, color=_COLORS.get(t["effect"]),
                      label=f"{_LABEL[t['effect']]}: {_value_text(t, axis)}")
        for t in r.get("unresolved") or []:
            ax.loglog(tt, np.sqrt(avar_term(t, tt)) * f, ":", lw=1.2, color=_COLORS.get(t["effect"]),
                      label=f"{_LABEL[t['effect']]}: not resolved by the record, kept in the model")
        nb = next((t for t in r.get("bounds") or [] if t["effect"] == "white_noise"), None)
        if nb is not None:
            # N not resolved: its bound is the least filter-corrected AVAR x tau (with its one-sided margin), so
            # the line reaches the data there and lies below them elsewhere; without it the sum below would miss
            # the short-tau points with nothing on the figure saying why
            ax.loglog(tt, np.sqrt(avar_term(nb, tt)) * f, "-.", lw=1.2, color=_COLORS["white_noise"],
                      label=f"white noise not resolved: N < {units.to_datasheet('N', nb['N'], axis):.3g} "
                            f"{units.datasheet_unit('N', axis)} (a bound, not in the sum)")
        ax.loglog(tt, np.sqrt(_model_avar(r, tt)) * f, "-", lw=1.6, color="tab:cyan",
                  label="sum of fitted terms" + (" (without N)" if nb is not None else ""))
        _ylim(ax, [r], f)
    q = r.get("quantization")
    if q:
        ax.loglog(tau, q["N_q"] / np.sqrt(tau) * f, color="0.5", lw=0.9, ls=":",
                  label=f"1-LSB rounding, N_q={units.to_datasheet('N', q['N_q'], axis):.3g} "
                        f"{units.datasheet_unit('N', axis)} ({'dithered' if q['dithered'] else 'NOT dithered'})")
    _label_axes(ax, axis)
    handles, labels = ax.get_legend_handles_labels()
    if legend_ax is not None:
        _legend_below(legend_ax, handles, labels)
    return handles, labels


def _stream_name(st: dict) -> str:
    return f"{st['message']}[{st['instance']}]"


def _panel_rows(axes_of) -> list[list[str]]:
    rows = [[a for a in names if axes_of(a)] for names in (GYRO_AXES, ACCEL_AXES)]
    return [r for r in rows if r]


def plot_stream(stream: dict, path, title: str | None = None) -> None:
    plt = require_matplotlib()
    save_figure(stream_figure(stream, title), path, plt)


def stream_figure(stream: dict, title: str | None = None):
    """One stream's detailed figure (a panel per axis, each term drawn, legends below the panels), unsaved."""
    plt = require_matplotlib()
    rows = _panel_rows(lambda a: a in stream["axes"])
    ncol = max(len(r) for r in rows)
    fig, gs, panels, strips = _grid(plt, rows, ncol, 5.2, 3.6)
    name = _stream_name(stream)
    labels = [[draw_axis(panels[i][j], axis, stream["axes"][axis], strips[i][j], name=name)[1]
               for j, axis in enumerate(row)] for i, row in enumerate(rows)]
    _fit_strips(fig, gs, 3.6, labels)
    src = f"{Path(stream['source']).name}: " if stream.get("source") else ""
    _suptitle(fig, title or (f"Allan deviation, {src}{name} sys{stream['sysid']}/comp{stream['compid']}, "
                             f"{stream['samples']} samples at {stream['rate_hz']:.4g} Hz "
                             f"({stream['duration_s']:.0f} s at rest)"), 11)
    return fig


def _stream_label(st: dict, several_sources: bool) -> str:
    lab = _stream_name(st)
    if several_sources and st.get("source"):
        lab = f"{Path(st['source']).name} {lab}"
    return lab


def _overlay_label(st: dict, several: bool, r: dict, axis: str) -> str:
    lab = _stream_label(st, several)
    nterm = next((t for t in r["terms"] if t["effect"] == "white_noise"), None)
    if nterm:
        lab += f", N={units.to_datasheet('N', nterm['N'], axis):.3g} {units.datasheet_unit('N', axis)}"
    else:
        nb = next((t for t in r.get("bounds") or [] if t["effect"] == "white_noise"), None)
        if nb:
            lab += (f", N < {units.to_datasheet('N', nb['N'], axis):.3g} {units.datasheet_unit('N', axis)} "
                    "(not resolved)")
    note = misfit_text(r, axis)
    return lab + (f" -- {note}".replace(" (shaded)", "") if note else "")


def plot_overlay(report: dict, path) -> None:
    """Every stream of the report (every IMU of a log, and of several logs) in one figure: a panel per axis,
    each stream's measured ADEV (points and 95 % band) and its fitted model (line), legend with N."""
    plt = require_matplotlib()
    fig = overlay_figure(report)
    if fig is not None:
        save_figure(fig, path, plt)


def overlay_figure(report: dict):
    """The figure of :func:`plot_overlay`, unsaved; None when no stream has an axis to draw."""
    plt = require_matplotlib()
    streams = [st for st in report["streams"] if any(r.get("status") == "ok" for r in st["axes"].values())]
    several = len({st.get("source") for st in streams}) > 1

    def drawn(st, a):
        r = st["axes"].get(a)
        return r is not None and r.get("status") == "ok" and bool(r.get("tau"))

    rows = _panel_rows(lambda a: any(drawn(st, a) for st in streams))
    if not rows:
        return None
    ncol = max(len(r) for r in rows)
    fig, gs, panels, strips = _grid(plt, rows, ncol, 5.4, 3.8)
    labels = [[] for _ in rows]
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for i, row in enumerate(rows):
        for j, axis in enumerate(row):
            ax = panels[i][j]
            f = units.to_datasheet("B", 1.0, axis)
            shown = []
            for k, st in enumerate(streams):
                if not drawn(st, axis):
                    continue
                r = st["axes"][axis]
                shown.append(r)
                c = colors[k % len(colors)]  # one colour per stream on every panel
                tau = np.asarray(r["tau"])
                ax.fill_between(tau, np.asarray(r["adev_lo"]) * f, np.asarray(r["adev_hi"]) * f, color=c,
                                alpha=0.15, linewidth=0)
                ax.loglog(tau, np.asarray(r["adev"]) * f, "o", ms=3, color=c, zorder=3,
                          label=_overlay_label(st, several, r, axis))
                if r["terms"]:
                    tt = np.logspace(np.log10(tau[0]), np.log10(tau[-1]), 120)
                    ax.loglog(tt, np.sqrt(_model_avar(r, tt)) * f, "-", lw=1.1, color=c)
            ax.set_title(f"{axis} ({_axis_kind(axis)}), {len(shown)} stream{'s' if len(shown) > 1 else ''}",
                         fontsize=10)
            _ylim(ax, shown, f)
            _label_axes(ax, axis)
            handles, labs = ax.get_legend_handles_labels()
            _legend_below(strips[i][j], handles, labs)
            labels[i].append(labs)
    _fit_strips(fig, gs, 3.8, labels)
    srcs = sorted({Path(st.get("source") or report.get("source", "")).name for st in streams})
    _suptitle(fig, f"Allan deviation, {len(streams)} streams of {', '.join(srcs)} (points: measured with 95 % band; "
                   "lines: fitted model)", 10)
    return fig


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
