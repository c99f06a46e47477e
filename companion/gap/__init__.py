"""Simulation-vs-measurement gap workflow (numpy/scipy only): where a noise model and a measurement
disagree, which effect the model lacks, the model fixed and the gap shown to shrink.

Entry point: :func:`companion.gap.workflow.run_gap`. Modules, each importing only those before it (no
cycle): ``likelihood`` (the Measured curve, deviance, gap metric), ``candidates`` (maximum-likelihood
fits, overdispersion), ``compare`` (measured AVAR, EDF, disagreement regions), ``selection`` (every
explanation weighed by one criterion), ``explain`` (plain words), ``spectral`` (periodogram check),
``workflow`` (the iteration). See docs/gap.md.
"""

from companion.gap.workflow import GapResult, run_gap

__all__ = ["GapResult", "run_gap"]
