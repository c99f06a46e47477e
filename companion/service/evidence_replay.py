"""The fault detectors of ``run`` over a log for ``analyze --report``: the log replayed through a fresh
pipeline (default configuration, no state), and the evidence of every alarm it raises (the flagged IMUs)."""

from __future__ import annotations


def alarm_evidence(path, time_unit: str | None = None, log=None) -> list[dict]:
    """Evidence items (service.evidence_log) of the alarms the detectors raise over the log at ``path``."""
    from companion.mavlink.reporter import Reporter
    from companion.service.pipeline import Pipeline
    from companion.service.pipeline_config import PipelineConfig
    from companion.service.replay import replay_log, replay_tlog
    from companion.service.run_session import ReplaySink
    from companion.sources.kind import kind_of

    pipeline = Pipeline(PipelineConfig(), Reporter(ReplaySink()), None, log)
    if kind_of(path) == "tlog":
        replay_tlog(path, pipeline)
    else:
        replay_log(path, pipeline, time_unit=time_unit)
    pipeline.evidence.finish()
    items = pipeline.evidence.all_items()
    for it in items:
        it["source"] = "analyze"
        it["log"] = str(path)
    return items
