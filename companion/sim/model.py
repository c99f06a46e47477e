"""Noise-model files: load, validate and save the YAML that the simulator and the gap workflow read.

Format (SI units, canonical vocabulary of :mod:`companion.allan.terms`)::

    rate_hz: 100.0
    axes:
      gx:
        - {effect: white_noise, N: 1.0e-3}
        - {effect: bias_instability, B: 2.0e-5}
        - {effect: gauss_markov, sigma: 1.0e-4, tau_c: 20.0}

Axes are gx, gy, gz (rad/s) and ax, ay, az (m/s^2). Every problem (invalid YAML, unknown key or effect,
missing or non-numeric parameter) raises :class:`companion.errors.CompanionError` naming the file, the
line and the key. PyYAML reads ``1e-3`` (no dot) as a string; such strings are accepted as numbers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from companion.allan.terms import EFFECTS, validate_term
from companion.errors import CompanionError, not_text

AXES = ("gx", "gy", "gz", "ax", "ay", "az")
_LINE = "__line__"


@dataclass
class NoiseModel:
    """A noise model: sample rate and, per axis, a list of term dicts (SI)."""

    rate_hz: float
    axes: dict[str, list[dict]] = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {"rate_hz": float(self.rate_hz), "axes": {a: [dict(t) for t in ts] for a, ts in self.axes.items()}}


class _LineLoader(yaml.SafeLoader):
    """SafeLoader that records the (1-based) line of every mapping under the key ``__line__``."""


def _construct_mapping(loader, node, deep=False):
    mapping = yaml.SafeLoader.construct_mapping(loader, node, deep=True)
    mapping[_LINE] = node.start_mark.line + 1
    return mapping


_LineLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)


def _number(value):
    """YAML number, or a string PyYAML did not take for one (``1e-3``); else None."""
    if isinstance(value, bool):
        return None
    if isinstance(value, (int, float)):
        return float(value)
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            return None
    return None


def _strip(obj):
    if isinstance(obj, dict):
        return {k: _strip(v) for k, v in obj.items() if k != _LINE}
    if isinstance(obj, list):
        return [_strip(v) for v in obj]
    return obj


def model_from_dict(d, source: str = "model") -> NoiseModel:
    """Validate a dict (as loaded from YAML) and build a :class:`NoiseModel`; errors name the key and line."""

    def where(obj, key):
        line = obj.get(_LINE) if isinstance(obj, dict) else None
        return f"{source}" + (f" line {line}" if line else "") + f": {key}"

    if not isinstance(d, dict):
        raise CompanionError(f"{source}: expected a mapping with 'rate_hz' and 'axes'")
    unknown = sorted(set(d) - {"rate_hz", "axes", _LINE})
    if unknown:
        raise CompanionError(f"{where(d, unknown[0])}: unknown key (expected rate_hz, axes)")
    if "rate_hz" not in d:
        raise CompanionError(f"{where(d, 'rate_hz')}: missing (sample rate in Hz)")
    rate = _number(d["rate_hz"])
    if rate is None or not math.isfinite(rate) or rate <= 0:
        raise CompanionError(f"{where(d, 'rate_hz')}: must be a positive number, got {d['rate_hz']!r}")
    axes = d.get("axes")
    if not isinstance(axes, dict) or not [a for a in axes if a != _LINE]:
        raise CompanionError(f"{where(d, 'axes')}: missing or empty (a mapping axis -> list of terms)")
    out: dict[str, list[dict]] = {}
    for axis, terms in axes.items():
        if axis == _LINE:
            continue
        if axis not in AXES:
            raise CompanionError(f"{where(axes, 'axes.' + str(axis))}: unknown axis (expected {', '.join(AXES)})")
        if terms is None:
            terms = []
        if not isinstance(terms, list):
            raise CompanionError(f"{where(axes, 'axes.' + axis)}: expected a list of terms like "
                                 "- {effect: white_noise, N: 1.0e-3}")
        clean = []
        for i, term in enumerate(terms):
            key = f"axes.{axis}[{i}]"
            if not isinstance(term, dict):
                raise CompanionError(f"{where(axes, key)}: expected a mapping like {{effect: white_noise, N: 1.0e-3}}")
            if "effect" not in term:
                raise CompanionError(f"{where(term, key)}: missing 'effect' (one of {', '.join(EFFECTS)})")
            t = {"effect": term["effect"]}
            for k, v in term.items():
                if k in ("effect", _LINE):
                    continue
                num = _number(v)
                t[k] = num if num is not None else v
            try:
                validate_term(t)
            except ValueError as exc:
                raise CompanionError(f"{where(term, key)}: {exc}") from None
            clean.append(t)
        out[axis] = clean
    return NoiseModel(rate_hz=rate, axes=out)


def load_model(path) -> NoiseModel:
    """Read and validate a model YAML file."""
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as exc:
        raise CompanionError(f"cannot read model {p}: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise not_text(p, exc, "a noise model is a YAML file (e.g. companion/examples/sample_model.yaml)") from None
    try:
        data = yaml.load(text, Loader=_LineLoader)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = f" line {mark.line + 1}" if mark else ""
        raise CompanionError(f"{p}{line}: invalid YAML: {exc.problem or exc.context}") from None
    except yaml.YAMLError as exc:
        raise CompanionError(f"{p}: invalid YAML: {exc}") from None
    return model_from_dict(data, source=str(p))


def save_model(model: NoiseModel, path, header: str | None = None) -> None:
    """Write a model as YAML (one flow mapping per term); ``header`` lines become leading comments."""
    lines = []
    if header:
        lines += ["# " + h if h else "#" for h in header.splitlines()]
    lines.append(f"rate_hz: {float(model.rate_hz)!r}")
    lines.append("axes:")
    for axis, terms in model.axes.items():
        lines.append(f"  {axis}:" + ("" if terms else " []"))
        for t in terms:
            items = ", ".join(f"{k}: {_fmt(v)}" for k, v in t.items())
            lines.append(f"    - {{{items}}}")
    Path(path).write_text("\n".join(lines) + "\n")


def _fmt(v):
    if isinstance(v, str):
        return v
    return repr(float(v)) if "e" in repr(float(v)) or "." in repr(float(v)) else f"{float(v):.1f}"
