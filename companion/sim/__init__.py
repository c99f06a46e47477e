"""Noise synthesis (numpy only, :mod:`companion.sim.synth`) and noise-model files (:mod:`companion.sim.model`)."""

from pathlib import Path

#: the shipped vehicle presets, one YAML per name (:mod:`companion.sim.preset`)
PRESET_DIR = Path(__file__).with_name("presets")


def preset_names() -> tuple[str, ...]:
    """Names of the shipped presets, read from :data:`PRESET_DIR` so that help texts and errors list every
    preset file without a second hand-kept list (kept free of numpy: the --help texts call it)."""
    return tuple(sorted(p.stem for p in PRESET_DIR.glob("*.yaml")))
