"""``companion gap`` on a log (adapter layer: it reads the log, the model file and the datasheet table):
load any input ``analyze`` reads, select the still segments as ``analyze`` does, pick the IMU stream, and
run the gap workflow (:func:`companion.gap.workflow.run_gap`) on each axis; write the updated model.
The words and the JSON are :mod:`companion.gap.log_text`'s."""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field, fields

from companion.errors import CompanionError
from companion.gap import log_text
from companion.gap.gap_result import GapResult
from companion.gap.sensor_model import sensor_terms
from companion.gap.workflow import run_gap
from companion.samples import GYRO_AXES


@dataclass
class GapLogOptions:
    """The choices of a gap run on a log (the options of ``companion gap``)."""

    measured: str
    model: str | None = None
    datasheet: str | None = None
    axis: str | None = None
    imu: int | None = None
    stream: str | None = None
    lsb: float | None = None
    cutoff: float | None = None
    start: float | None = None
    end: float | None = None
    use_all: bool = False
    seed: int = 0
    config: str | None = None
    time_unit: str | None = None

    @classmethod
    def from_args(cls, args) -> GapLogOptions:
        return cls(**{f.name: getattr(args, f.name, f.default) for f in fields(cls)})


@dataclass
class LogGap:
    """The model and the log's still data, ready for the workflow."""

    opts: GapLogOptions
    model: object  #: companion.sim.model.NoiseModel
    sheet: dict | None  #: the datasheet entry, when the model came from one
    axes: list
    stream: object  #: the IMU stream
    ranges: list  #: [a, b) sample ranges of the still segments in the stream
    selection: object  #: companion.sources.still selection
    source_model: str
    cutoff_hz: float | None
    #: PX4 sensor_combined carries gyro_rad = integral / integral_dt: each value is a mean over its interval
    integrated: bool
    rate_hz: float = field(init=False)

    def __post_init__(self):
        self.rate_hz = float(self.stream.rate_hz)

    @property
    def label(self) -> str:
        return self.stream.key.label()


@dataclass
class AxisGap:
    """One axis compared: the workflow's result, its report, its JSON document, the sensor's terms."""

    axis: str
    result: GapResult
    text: str
    doc: dict
    sensor_terms: list
    left_out: list


def _pick_stream(spec, streams, sel, opts: GapLogOptions):
    """The IMU stream asked for (--imu/--stream), else the one with the most still samples."""
    if opts.imu is not None:
        hits = [s for s in streams if s.key.instance == opts.imu]
        if not hits:
            raise CompanionError(f"{spec}: no IMU instance {opts.imu} (has: "
                                 f"{', '.join(s.key.label() for s in streams)})")
        return max(hits, key=lambda s: s.samples)
    if opts.stream:
        want = opts.stream.lower()
        hits = [s for s in streams if s.key.label().lower().startswith(want) or s.key.message.lower() == want]
        if not hits:
            raise CompanionError(f"{spec}: no IMU stream {opts.stream!r} (has: "
                                 f"{', '.join(s.key.label() for s in streams)})")
        return hits[0]
    return max(streams, key=lambda s: sum(b - a for a, b in sel.ranges(s)))


@dataclass
class MeasuredLog:
    """The IMU stream picked from a log and its still segments."""

    stream: object
    ranges: list  #: [a, b) sample ranges of the still segments in the stream
    selection: object  #: the still selection (companion.sources.still)
    meta: dict  #: the log's metadata (format, parameters)


def load_measured(spec, opts: GapLogOptions) -> MeasuredLog:
    """Load any input ``analyze`` reads, select the still segments (:func:`companion.sources.still.select_still`,
    the same selection as ``companion analyze``), pick the stream."""
    from companion.sources import load
    from companion.sources.still import select_still

    res = load(spec, config=opts.config, time_unit=opts.time_unit)
    streams = res.imu_streams()
    if not streams:
        raise CompanionError(f"{spec}: no IMU stream")
    sel = select_still(streams, res.meta, start=opts.start, end=opts.end, use_all=opts.use_all)
    if not sel.intervals:
        raise CompanionError(f"{spec}: {sel.notes[0] if sel.notes else 'no still data'} ({sel.describe()})")
    st = _pick_stream(spec, streams, sel, opts)
    ranges = sel.ranges(st)
    if not ranges:
        raise CompanionError(f"{spec}: {st.key.label()} has no samples in the still segments ({sel.describe()})")
    rate = st.rate_hz
    if not (rate and math.isfinite(rate) and rate > 0):
        raise CompanionError(f"{spec}: cannot determine the sample rate of {st.key.label()}")
    return MeasuredLog(st, ranges, sel, res.meta)


def log_cutoff(stream, meta) -> float | None:
    """The gyro low-pass cut-off of the logged data from the log's parameters (None if unknown)."""
    from companion.analysis.stream import stream_filters

    return stream_filters(stream, meta).get("gyro")


def _axes(opts: GapLogOptions, model_axes: list, sheet) -> list:
    """The axes to compare (--axis, else every gyro axis of the model), each one the model has."""
    axes = [opts.axis] if opts.axis else [a for a in GYRO_AXES if a in model_axes]
    for a in axes:
        if a in model_axes:
            continue
        if sheet is not None:
            raise CompanionError(f"datasheet {sheet['name']}: no terms for axis {a}; datasheet models are gyro-only "
                                 f"(has: {', '.join(model_axes)}); for an accelerometer axis give --model")
        raise CompanionError(f"{opts.model}: no terms for axis {a} (has: {', '.join(model_axes) or 'none'})")
    if not axes:
        raise CompanionError(f"{opts.model}: no gyro axis; give --axis")
    return axes


def prepare(opts: GapLogOptions) -> LogGap:
    """The model (file or datasheet) and the log's still data. The model and the axis are checked before
    the log is read: a wrong path or --axis fails at once, not after a long load."""
    from companion.sim.model import NoiseModel, load_model

    sheet = terms = model = None
    if opts.datasheet:
        from companion.datasheets import model_terms

        terms, sheet = model_terms(opts.datasheet)
        model_axes = list(GYRO_AXES)  # the datasheet table holds gyro figures only
    else:
        model = load_model(opts.model)
        model_axes = list(model.axes)
    axes = _axes(opts, model_axes, sheet)
    m = load_measured(opts.measured, opts)
    st, meta = m.stream, m.meta
    if sheet is not None:
        model = NoiseModel(rate_hz=float(st.rate_hz), axes={a: [dict(t) for t in terms] for a in GYRO_AXES})
        source_model = f"datasheet {sheet['name']} ({sheet['source']}; N from {sheet['si']['N_from']}" + \
            (f", B from {sheet['si']['B_from']}" if sheet["si"]["B"] else ", no bias stability given") + ")"
    else:
        source_model = opts.model
    cutoff = opts.cutoff if opts.cutoff is not None else log_cutoff(st, meta)
    if opts.cutoff is not None and not opts.cutoff < float(st.rate_hz) / 2:  # checked before the fits
        raise CompanionError(f"--cutoff {opts.cutoff:g} Hz: at or above the Nyquist frequency of {st.key.label()} "
                             f"({float(st.rate_hz):.4g} Hz data: at most {float(st.rate_hz) / 2:.4g} Hz); give the "
                             "filter's cut-off below it, or leave --cutoff out")
    integrated = meta.get("format") == "ulog" and st.key.message == "sensor_combined"
    return LogGap(opts=opts, model=model, sheet=sheet, axes=axes, stream=st, ranges=m.ranges, selection=m.selection,
                  source_model=source_model, cutoff_hz=cutoff, integrated=integrated)


def _context(lg: LogGap) -> log_text.LogContext:
    st = lg.stream
    return log_text.LogContext(
        source=str(lg.opts.measured), label=lg.label, source_model=lg.source_model,
        selection_text=lg.selection.describe(), selection=lg.selection.to_dict(),
        ranges_s=[[float(st.t[a]), float(st.t[b - 1])] for a, b in lg.ranges], cutoff_hz=lg.cutoff_hz,
        cutoff_from_option=lg.opts.cutoff is not None, model_rate_hz=lg.model.rate_hz, rate_hz=lg.rate_hz,
        sheet=lg.sheet)


def measured_white(lg: LogGap, axis: str, lsb) -> tuple[dict | None, float | None, int]:
    """The analysis of the same still data (:func:`companion.analysis.stream.axis_entry`, what ``companion
    analyze`` reports): its white level {"N", "ci95", "bound"} (None where the analysis has no N), and the
    low-pass the gap's filter candidate takes (cut-off, order): --cutoff when given; where the log names a
    filter, the analysis' (the log's parameter, or the data's own roll-off where the data disagree with it);
    where it names none, None (the workflow fits the cut-off beside the other candidates, a vibration line near
    the logger's Nyquist frequency among them)."""
    from companion.analysis.stream import axis_entry

    cutoffs = {"gyro": lg.cutoff_hz, "accel": lg.cutoff_hz} if lg.cutoff_hz else {}
    e = axis_entry(lg.stream, axis, lg.ranges, cutoffs, lsb=lsb)
    wn = next((t for t in e.get("terms", []) if t["effect"] == "white_noise"), None)
    if wn is None:
        b = next((t for t in e.get("bounds", []) if t["effect"] == "white_noise"), None)
        white = {"N": None, "bound": float(b["N"])} if b else None
        return white, lg.cutoff_hz, 2
    white = {"N": float(wn["N"]), "ci95": list(wn.get("ci95", {}).get("N", [wn["N"], wn["N"]]))}
    if lg.opts.cutoff is None and lg.cutoff_hz and wn.get("filter_hz"):
        return white, float(wn["filter_hz"]), int(wn.get("filter_order", 2))
    return white, lg.cutoff_hz, 2


def _data_rolloff(r: GapResult, cutoff: float, order: int, param: float) -> None:
    """Say where the filter candidate's cut-off came from when it is the analysis' fit of the data's own
    roll-off rather than the log's parameter."""
    src = "the data's roll-off, as companion analyze fits it"
    for a in r.added:
        if a.get("effect") == "lowpass":
            a["source"] = src
            a["explanation"] = a["explanation"].replace("(the log's parameter)", f"({src})")
    r.notes.append(f"low-pass filter candidate at {cutoff:.3g} Hz, order {order}: the data's own roll-off as the "
                   f"analysis fits it (the log's {param:.3g} Hz set aside: the data disagree with it)")


def run_axis(lg: LogGap, axis: str) -> AxisGap:
    """The workflow on one axis of the log's still segments, pooled, with the analysis' white level of the same
    data (:func:`measured_white`) as the model's N and the datasheet verdict's."""
    st, opts = lg.stream, lg.opts
    segs, tsegs = log_text.still_segments(st.axis(axis), getattr(st, "temperature", None), lg.ranges,
                                          opts.measured, axis)
    lsb = opts.lsb if opts.lsb is not None else (st.gyro_lsb if axis in GYRO_AXES else st.accel_lsb)
    white, cutoff, order = measured_white(lg, axis, lsb)
    r = run_gap(None, lg.rate_hz, lg.model.axes[axis], axis=axis, lsb=lsb, seed=opts.seed, cutoff_hz=cutoff,
                filter_order=order, segments=segs, temperature=tsegs or None, integrated=lg.integrated,
                white=white if white and white.get("N") else None)
    r.white = white
    if cutoff and cutoff != lg.cutoff_hz:
        _data_rolloff(r, cutoff, order, lg.cutoff_hz)
    ctx = _context(lg)
    text = log_text.axis_text(r, ctx)
    # the sensor's terms only: the log's rate rounding, filter and temperature coupling are derived from
    # the log on every run, and written into the model they would be counted twice when read back
    terms, left = sensor_terms(r)
    return AxisGap(axis=axis, result=r, text=text, doc=log_text.axis_doc(r, ctx, text), sensor_terms=terms,
                   left_out=left)


def run_axes(lg: LogGap) -> Iterator[AxisGap]:
    """:func:`run_axis` on each axis in turn (each is reported as it is done)."""
    for axis in lg.axes:
        yield run_axis(lg, axis)


def write_updated_model(lg: LogGap, runs: list[AxisGap], path) -> list[str]:
    """Write the sensor's updated model at the data's rate_hz: every term was evaluated at it (a bias
    instability without f0 up to its Nyquist frequency), and ``companion simulate`` synthesises the model
    at its rate_hz. Other axes' terms unchanged. Returns the log's own terms left out, per axis."""
    from companion.sim.model import NoiseModel, save_model

    new_axes = {a: [dict(t) for t in ts] for a, ts in lg.model.axes.items()}
    left_out = {}
    for run in runs:
        new_axes[run.axis], left_out[run.axis] = run.sensor_terms, run.left_out
    left = log_text.left_lines(left_out)
    header = log_text.model_header(lg.opts.measured, lg.label, lg.axes, [r.doc for r in runs], lg.rate_hz,
                                   lg.model.rate_hz, left)
    try:
        save_model(NoiseModel(rate_hz=lg.rate_hz, axes=new_axes), path, header=header)
    except OSError as exc:
        raise CompanionError(f"cannot write {path}: {exc.strerror or exc}") from None
    return left
