"""Offline noise analysis (what ``companion analyze`` and the fleet task compute), free of argument parsing
and printing: per-axis Allan fit (:mod:`.axis`), per-stream entries (:mod:`.stream`), --taus cluster sizes
(:mod:`.taus`), one source end to end (:mod:`.source`), the inspect notes (:mod:`.notes`), the text table
(:mod:`.report_table`) and the Kalibr file (:mod:`.kalibr`). Submodules import numpy; scipy only where a fit runs."""
