"""The session folder: its name, its layout, summary.json (no ROS)."""

from __future__ import annotations

import json
import math
from datetime import datetime
from pathlib import Path

import pytest

from hri_physio_bringup.folder import SessionFolder

START = datetime(2026, 5, 4, 10, 30, 0)


def test_the_folder_is_named_after_the_participant_and_the_start(tmp_path: Path) -> None:
    folder = SessionFolder.plan(tmp_path / "sessions", "P-0123456789", START)
    assert folder.path == tmp_path / "sessions" / "P-0123456789_2026-05-04_10-30-00"
    assert not folder.path.exists()  # planned, not made: nothing exists before the checks
    folder.create()
    assert {p.name for p in folder.path.iterdir()} == {"logs", "configs"}
    assert folder.bag == folder.path / "bag"
    assert folder.log_file("hr_receiver") == folder.path / "logs" / "hr_receiver.log"
    assert folder.config_file("qt_physio_coach") == folder.path / "configs" / "qt_physio_coach.yaml"


def test_a_second_session_in_the_same_second_gets_its_own_folder(tmp_path: Path) -> None:
    first = SessionFolder.plan(tmp_path, "P-1", START)
    first.create()
    second = SessionFolder.plan(tmp_path, "P-1", START)
    assert second.path.name == "P-1_2026-05-04_10-30-00_2"
    second.create()
    with pytest.raises(FileExistsError):
        first.create()  # a folder is never reused


def test_summary_json_is_strict_json_replaced_whole(tmp_path: Path) -> None:
    folder = SessionFolder.plan(tmp_path, "P-1", START)
    folder.create()
    folder.write_summary({"outcome": "running", "hr": math.nan})
    path = folder.write_summary({"outcome": "finished", "hr": math.inf, "bag": folder.bag,
                                 "counts": {"a": [1.0, math.nan]}})
    assert json.loads(path.read_text()) == {"outcome": "finished", "hr": None, "bag": str(folder.bag),
                                            "counts": {"a": [1.0, None]}}
    assert [p.name for p in folder.path.iterdir() if p.is_file()] == ["summary.json"]  # no temp file left


def test_configs_are_written_as_given(tmp_path: Path) -> None:
    folder = SessionFolder.plan(tmp_path, "P-1", START)
    folder.create()
    text = "qt_controller:\n  ros__parameters:\n    language: en-US\n"
    assert folder.write_config("qt_controller", text).read_text() == text


def test_the_path_is_shown_relative_to_where_the_user_is(tmp_path: Path) -> None:
    folder = SessionFolder.plan(tmp_path / "sessions", "P-1", START)
    assert folder.display(cwd=tmp_path) == "sessions/P-1_2026-05-04_10-30-00"
    assert folder.display(cwd=tmp_path / "elsewhere") == str(folder.path.resolve())


def test_an_out_folder_that_is_a_file_is_not_taken_for_a_name_taken(tmp_path: Path) -> None:
    """``--out`` naming a file: NotADirectoryError naming it (one error line in the launcher), not the
    FileExistsError that makes the launcher try the next name, 100 times."""
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    for parent in (blocker, blocker / "sub"):
        folder = SessionFolder.plan(parent, "P-1", datetime(2026, 1, 2, 3, 4, 5))
        with pytest.raises(NotADirectoryError) as info:
            folder.create()
        assert info.value.filename == str(blocker)
