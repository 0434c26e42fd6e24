"""The report on a bag whose recorder was killed: no metadata.yaml, no MCAP summary, cut mid-record."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from helpers.session_bags import Recomputed, copy_real_bag, read_stream
from hri_physio_bridge import topics
from hri_physio_bridge.bag.metadata import METADATA_FILE
from hri_physio_coach.report import make_report
from hri_physio_coach.report.cli import main

HR_TOPIC = topics.POLAR_H10_HR


def _kill(bag: Path, keep: float) -> Path:
    """What a SIGKILL leaves: the first ``keep`` of the file (no summary, a torn last record)."""
    (bag / METADATA_FILE).unlink()
    mcap = next(bag.glob("*.mcap"))
    data = mcap.read_bytes()
    mcap.write_bytes(data[: int(len(data) * keep) + 7])  # +7: not on a record boundary
    return mcap


@pytest.fixture(scope="module")
def killed(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    bag = copy_real_bag(tmp_path_factory.mktemp("killed"))
    return bag, _kill(bag, 0.6)


def test_report_of_a_killed_recording_matches_what_the_file_holds(killed: tuple[Path, Path]) -> None:
    bag, mcap = killed
    result = make_report(bag, figures=False)
    report = result.report
    assert report["bag_complete"] is False
    assert any(METADATA_FILE in w for w in result.warnings)
    assert report["session"]["outcome"] == "incomplete"
    assert any("did not finish" in m for m in result.missing)
    # Numbers from what the file holds, read with the mcap library's stream reader.
    wanted = {topics.COACH_EVENTS, "/clock", HR_TOPIC}
    independent = Recomputed.from_messages(read_stream(mcap, wanted), HR_TOPIC)
    assert independent.hr_bpm.size > 300 and independent.of("zone")
    assert report["hr_rest"] == pytest.approx(independent.of("zone")[-1]["hr_rest"], abs=0.01)
    expected = independent.in_zone()
    for kind in ("warm_up", "conditioning", "cool_down"):
        if kind in expected:
            assert report["in_zone_fraction"][kind] == pytest.approx(expected[kind], abs=1e-4), kind
        else:
            assert report["in_zone_fraction"][kind] is None, kind  # the recording ended before it
    assert report["adaptations"]["rule_updates"] == len(independent.of("rule_update"))
    assert report["streams"][HR_TOPIC]["received"] == independent.hr_bpm.size


def test_cli_on_the_mcap_file_of_a_killed_recording(killed: tuple[Path, Path], tmp_path: Path) -> None:
    _bag, mcap = killed
    out = tmp_path / "out"
    assert main([str(mcap), "--out", str(out), "--quiet"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["bag_complete"] is False
    assert (out / "hr_session.png").stat().st_size > 20_000
    html = (out / "report.html").read_text(encoding="utf-8")
    assert html.count("data:image/png;base64,") == len(report["figures"])


def test_recording_killed_during_calibration_reports_what_ran(tmp_path: Path, capsys) -> None:
    bag = copy_real_bag(tmp_path)
    _kill(bag, 0.18)
    assert main([str(bag), "--out", str(tmp_path / "out"), "--no-figures"]) == 0
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["zone"] is None and report["hr_rest"] is None
    assert report["in_zone_fraction"] == {"warm_up": None, "conditioning": None, "cool_down": None}
    assert [p["kind"] for p in report["phases"]] == ["calibration"]
    err = capsys.readouterr().err
    assert "no zone" in err and err.count("\n") >= 2  # one line per note, each on its own line
