"""Simulation-vs-measurement gap workflow (numpy/scipy only): where a noise model and a measurement
disagree, which effect the model lacks, the model fixed and the gap shown to shrink.

Entry point: :func:`companion.gap.workflow.run_gap`. Modules, each importing only those before it (no
cycle):

* the curve and the fits: ``likelihood`` (the Measured curve, deviance, gap metric), ``candidates``
  (maximum-likelihood fits, overdispersion), ``compare`` (measured AVAR, EDF, disagreement regions);
* one step's choice: ``scoring`` (the one criterion, the Explanation record), ``cutoff_fit`` (the
  low-pass filter as an explanation), ``ranking`` (every explanation from one state), ``selection``
  (the rules between look-alikes, in order; the StepChoice record);
* independent evidence and the workflow: ``spectral``, ``thermal``, ``trend``, ``arbitration``,
  ``rate_rounding``, ``backward`` (steps that take back), ``verdicts``, ``step_records``, ``result``,
  ``workflow`` (the steps over a small state);
* a run on a log: ``log_text`` (words and JSON) and ``from_log`` (adapter layer: loads the log and the
  model; not imported here, so the package stays core).

See docs/gap.md.
"""

from companion.gap.workflow import GapResult, run_gap

__all__ = ["GapResult", "run_gap"]
