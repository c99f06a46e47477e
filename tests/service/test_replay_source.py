"""Which sources `companion run` replays: a log by its name, or an existing file by its content (the one kind
rule of companion.sources.kind), never a connection string."""

import shutil
from pathlib import Path

from companion.service.replay import is_replay_source

SAMPLE = Path(__file__).resolve().parents[2] / "tlogs" / "sample.tlog"


def test_a_log_named_by_its_suffix_is_replayed_even_before_it_exists(tmp_path):
    assert is_replay_source(str(tmp_path / "flight.tlog"))
    assert is_replay_source(str(tmp_path / "flight.bin.gz"))


def test_a_tlog_saved_as_log_is_replayed_by_its_content(tmp_path):
    renamed = tmp_path / "flight.log"
    shutil.copyfile(SAMPLE, renamed)
    assert is_replay_source(str(renamed))


def test_connection_strings_and_unknown_files_are_not_replays(tmp_path):
    assert not is_replay_source("udpin:0.0.0.0:14550")
    assert not is_replay_source("tcp:127.0.0.1:5760")
    notes = tmp_path / "notes.log"
    notes.write_text("not a log at all\n")
    assert not is_replay_source(str(notes))
