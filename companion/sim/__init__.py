"""Noise synthesis (numpy only, :mod:`companion.sim.synth`) and noise-model files (:mod:`companion.sim.model`)."""
