"""Simulation-vs-measurement gap workflow (numpy/scipy only): where a noise model and a measurement
disagree, which effect the model lacks, the model fixed and the gap shown to shrink.

Entry point: :func:`companion.gap.workflow.run_gap`. Modules: ``compare`` (measured AVAR, EDF, gap metric,
disagreement regions), ``candidates`` (maximum-likelihood fits, evidence), ``explain`` (plain words),
``workflow`` (the iteration). See docs/gap.md.
"""

from companion.gap.workflow import GapResult, run_gap

__all__ = ["GapResult", "run_gap"]
