"""Vehicle presets (copter, plane, rover, px4): a YAML of a noise model, the vehicle and its
:class:`companion.sim.realism.Realism`, fitted to real logs (docs/vehicle.md). An adapter: it reads YAML, so it
lives apart from the numerical realism path."""

from __future__ import annotations

from pathlib import Path

from companion.errors import CompanionError
from companion.sim import PRESET_DIR
from companion.sim.realism import PRESETS, Realism, _err


def load_preset(name_or_path) -> dict:
    """A preset YAML as ``{"model": NoiseModel, "vehicle": {...}, "realism": Realism, "source": str}``;
    ``name_or_path`` is a shipped preset's name (``copter``, ``plane``, ``rover``, ``px4``: the YAML files of
    ``companion/sim/presets``) or a path to a file of the same form."""
    import yaml

    from companion.sim.model import model_from_dict

    p = Path(str(name_or_path))
    if str(name_or_path) in PRESETS:
        p = PRESET_DIR / f"{name_or_path}.yaml"
    if not p.is_file():
        raise _err(f"preset {name_or_path!r}: neither {', '.join(PRESETS)} nor a readable file")
    try:
        doc = yaml.safe_load(p.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise _err(f"preset {p}: cannot read it ({exc.__class__.__name__})") from None
    if not isinstance(doc, dict) or "model" not in doc:
        raise _err(f"preset {p}: expected a mapping with model, vehicle and realism")
    unknown = sorted(set(doc) - {"model", "vehicle", "realism", "fitted_to", "description"})
    if unknown:
        raise _err(f"preset {p}: unknown key {unknown[0]!r}")
    try:
        model = model_from_dict(doc["model"], str(p))
        realism = Realism.from_dict(doc.get("realism"))
    except CompanionError as exc:
        raise _err(f"preset {p}: {exc}") from None
    vehicle = dict(doc.get("vehicle") or {})
    bad = sorted(set(vehicle) - {"imus", "rate_hz", "max_rate", "flight_vibration"})
    if bad:
        raise _err(f"preset {p}: vehicle: unknown key {bad[0]!r}")
    return {"model": model, "vehicle": vehicle, "realism": realism, "source": str(p),
            "fitted_to": doc.get("fitted_to"), "description": doc.get("description")}
