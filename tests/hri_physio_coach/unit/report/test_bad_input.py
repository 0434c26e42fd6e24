"""Bad input to hri_physio_report: one line on stderr naming the problem, exit 2, nothing written."""

from __future__ import annotations

from pathlib import Path

import pytest

from helpers.session_bags import REAL_BAG, BagBuilder, copy_real_bag
from hri_physio_bridge.bag.writer import BagWriter
from hri_physio_coach.report.cli import main


def _run(args: list[str], capsys) -> tuple[int, str]:
    code = main(args)
    err = capsys.readouterr().err
    return code, err


def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("hri_physio_report: error: ")
    return lines[0]


def test_missing_path(tmp_path: Path, capsys) -> None:
    code, err = _run([str(tmp_path / "nope")], capsys)
    assert code == 2 and "does not exist" in _one_line(err)


def test_not_a_bag_file(tmp_path: Path, capsys) -> None:
    (tmp_path / "notes.txt").write_text("hello")
    code, err = _run([str(tmp_path / "notes.txt")], capsys)
    assert code == 2 and "notes.txt" in _one_line(err)


def test_folder_without_a_bag(tmp_path: Path, capsys) -> None:
    (tmp_path / "logs").mkdir()
    code, err = _run([str(tmp_path)], capsys)
    assert code == 2 and "holds no bag" in _one_line(err)
    assert list(tmp_path.iterdir()) == [tmp_path / "logs"]


def test_session_folder_with_two_bags(tmp_path: Path, capsys) -> None:
    copy_real_bag(tmp_path)
    (tmp_path / "second").mkdir()
    (tmp_path / "second" / "x.mcap").write_bytes(b"")
    code, err = _run([str(tmp_path)], capsys)
    assert code == 2 and "2 bags" in _one_line(err)


def test_garbage_mcap(tmp_path: Path, capsys) -> None:
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "bag_0.mcap").write_bytes(b"this is not an MCAP file at all" * 10)
    code, err = _run([str(bag)], capsys)
    assert code == 2 and "bag_0.mcap" in _one_line(err)
    assert not (tmp_path / "report.json").exists()


def test_empty_bag(tmp_path: Path, capsys) -> None:
    BagWriter(tmp_path / "empty").close()
    code, err = _run([str(tmp_path / "empty")], capsys)
    assert code == 2 and "no messages" in _one_line(err)


def test_bag_without_coach_events(tmp_path: Path, capsys) -> None:
    b = BagBuilder()
    b.event(10**18, {"t": 1.0, "event": "window"}, topic="/physio/polar_h10/ecg/status")
    bag = b.write(tmp_path / "bag")
    code, err = _run([str(bag)], capsys)
    assert code == 2 and "no coach events" in _one_line(err)


def test_unwritable_output(tmp_path: Path, capsys) -> None:
    (tmp_path / "file").write_text("x")
    code, err = _run([str(REAL_BAG), "--out", str(tmp_path / "file" / "sub"), "--no-figures"], capsys)
    assert code == 2 and "cannot create" in _one_line(err)


@pytest.mark.parametrize("argv", [[], ["a", "b"], ["--bogus", "x"]])
def test_bad_arguments(argv: list[str], capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("hri_physio_report: error:"), lines
