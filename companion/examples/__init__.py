"""Files shipped inside the package, so that an installed wheel has them without the source tree.

``default_config.yaml`` states every configuration key with its default (companion/config.py is the schema; a
test keeps the two equal); ``sample_model.yaml`` is the noise model the README's sample log was made from.
``companion example NAME`` prints or writes them.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

#: name on the command line -> (file in this package, what it is)
EXAMPLES = {
    "config": ("default_config.yaml", "every configuration key with its default (run, inspect, analyze, gap, compensate: --config)"),
    "model": ("sample_model.yaml", "a noise model for simulate and gap --model (an ArduPilot-like MEMS gyro)"),
}


def text(name: str) -> str:
    """The text of the shipped example ``name`` (a key of :data:`EXAMPLES`)."""
    filename, _ = EXAMPLES[name]
    return resources.files(__name__).joinpath(filename).read_text(encoding="utf-8")


def path(name: str) -> Path:
    """The file of the shipped example ``name``, where the package is installed as plain files (tests)."""
    filename, _ = EXAMPLES[name]
    return Path(__file__).with_name(filename)
