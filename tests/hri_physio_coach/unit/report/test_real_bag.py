"""hri_physio_report on a real session bag: numbers against an independent recomputation, figures, page."""

from __future__ import annotations

import base64
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from matplotlib.colors import to_rgb
from matplotlib.image import imread

from helpers.session_bags import REAL_BAG, Recomputed, read_anyreader
from hri_physio_bridge import topics
from hri_physio_coach.report import make_report
from hri_physio_coach.report.cli import main
from hri_physio_coach.report.figures import PHASE_COLORS, ZONE_COLOR

HR_TOPIC = topics.POLAR_H10_HR


@pytest.fixture(scope="module")
def session_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A session folder as hri_physio_session lays it out: the bag and configs/*.yaml."""
    folder = tmp_path_factory.mktemp("report") / "P01_2026-11-23_18-53-14"
    shutil.copytree(REAL_BAG, folder / REAL_BAG.name)
    (folder / "configs").mkdir()
    (folder / "configs" / "qt_physio_coach.yaml").write_text(
        f"hr_topic: {HR_TOPIC}\npolicy: fuzzy\npart_age: 33.0\n", encoding="utf-8")
    return folder


@pytest.fixture(scope="module")
def result(session_dir: Path):
    return make_report(session_dir)


@pytest.fixture(scope="module")
def independent() -> Recomputed:
    wanted = {topics.COACH_EVENTS, "/clock", HR_TOPIC}
    return Recomputed.from_messages(read_anyreader(REAL_BAG, wanted), HR_TOPIC)


def test_required_numbers_match_an_independent_computation(result, independent: Recomputed) -> None:
    report = json.loads((result.out_dir / "report.json").read_text())
    zone = independent.of("zone")[-1]
    assert report["hr_rest"] == pytest.approx(zone["hr_rest"], abs=0.01)
    assert report["hr_max"] == pytest.approx(208 - 0.7 * 33, abs=0.01)  # Tanaka, age 33
    assert report["zone"]["low"] == pytest.approx(zone["low"], abs=0.01)
    assert report["zone"]["high"] == pytest.approx(zone["high"], abs=0.01)
    expected = independent.in_zone()
    assert set(report["in_zone_fraction"]) == {"warm_up", "conditioning", "cool_down"}
    for kind in ("warm_up", "conditioning", "cool_down"):
        assert report["in_zone_fraction"][kind] == pytest.approx(expected[kind], abs=1e-4), kind
        assert 0.0 <= report["in_zone_fraction"][kind] <= 1.0
    # The fractions differ between phases: the warm-up starts far below the zone.
    assert report["in_zone_fraction"]["warm_up"] < report["in_zone_fraction"]["conditioning"]


def test_seconds_above_and_samples_per_phase(result, independent: Recomputed) -> None:
    report = result.report
    zone = independent.of("zone")[-1]
    t = independent.session_time(independent.hr_ns)
    above = 0
    for kind, a, b in independent.phase_windows():
        sel = (t >= a) & (t < b)
        entry = next(p for p in report["phases"] if p["kind"] == kind)
        assert entry["hr_samples"] == int(sel.sum()), kind
        if kind != "calibration":
            above += int(np.sum(independent.hr_bpm[sel] > zone["high"]))
    period = float(np.median(np.diff(independent.hr_source_t)))
    assert report["seconds_above_hrr70"] == pytest.approx(above * period, abs=0.05)


def test_adaptations_behaviours_and_data_loss(result, independent: Recomputed) -> None:
    report = result.report
    updates = independent.of("rule_update")
    assert report["adaptations"]["rule_updates"] == len(updates) == 39
    plans = [p for p in independent.of("plan") if p["decision"]["changed"]]
    assert report["adaptations"]["total"] == sum(1 for u in updates if u["decision"]["changed"]) + len(plans)
    assert report["adaptations"]["planned_changes"] == len(plans)
    for phase in ("warm_up", "conditioning", "cool_down"):
        mine = report["adaptations"]["per_phase"][phase]
        theirs = [u for u in updates if u["inputs"]["phase"] == phase]
        assert mine["rule_updates"] == len(theirs)
        assert mine["speed up"] == sum(1 for u in theirs if u["decision"]["delta"] > 0)
    kinds: dict[str, int] = {}
    for b in independent.of("behaviour"):
        kinds[b["kind"]] = kinds.get(b["kind"], 0) + 1
    assert report["behaviours"]["by_kind"] == kinds
    hr = report["streams"][HR_TOPIC]
    assert hr["received"] == independent.hr_bpm.size
    src = np.sort(independent.hr_source_t)
    assert hr["rate_hz"] == 1.0  # the strap's HR: one value a second
    assert hr["expected"] == round(src[-1] - src[0]) + 1
    assert hr["missing"] == max(hr["expected"] - np.unique(src).size, 0)
    assert report["policy"] == "fuzzy"
    assert report["hr_topic"] == HR_TOPIC and report["hr_topic_from"] == "configs/qt_physio_coach.yaml"
    assert report["session"]["outcome"] == "finished"
    assert report["session"]["duration_s"] == pytest.approx(1380.0, abs=0.5)


def _rgb(path: Path) -> np.ndarray:
    img = imread(path)
    return np.round(img[..., :3] * 255).astype(int)


def _share(img: np.ndarray, color: str) -> float:
    want = np.round(np.array(to_rgb(color)) * 255).astype(int)
    return float(np.mean(np.all(np.abs(img - want) <= 2, axis=-1)))


def test_hr_session_figure_shows_zone_phases_and_markers(result) -> None:
    path = result.files["hr_session"]
    assert path.name == "hr_session.png" and path.stat().st_size > 50_000
    img = _rgb(path)
    assert img.shape[0] >= 900 and img.shape[1] >= 1600
    assert _share(img, ZONE_COLOR) > 0.05  # the zone band is a large part of the figure
    for kind in ("calibration", "warm_up", "conditioning", "cool_down"):
        assert _share(img, PHASE_COLORS[kind]) > 0.002, kind  # the phase strip
    assert _share(img, "#2a9d3c") > 0  # speed-up markers (green)


def test_fuzzy_figures_exist_and_differ(result) -> None:
    curve, overlay = result.files["fuzzy_probability"], result.files["fuzzy_overlay"]
    for path in (curve, overlay):
        img = _rgb(path)
        assert img.shape[0] > 500
        assert _share(img, ZONE_COLOR) > 0.02
        packed = (img[..., 0] << 16) | (img[..., 1] << 8) | img[..., 2]
        assert np.unique(packed).size > 200  # not a blank canvas
    assert curve.read_bytes() != overlay.read_bytes()


def test_html_page_is_self_contained_with_figures_table_and_configuration(result) -> None:
    html = (result.out_dir / "report.html").read_text(encoding="utf-8")
    images = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', html)
    assert len(images) == len(result.report["figures"]) == 3
    for data in images:
        assert base64.b64decode(data)[:8] == b"\x89PNG\r\n\x1a\n"
    assert not re.search(r'(src|href)="(https?:|/|\.\.?/)', html)  # nothing loaded from elsewhere
    assert "part_age: 33.0" in html and "qt_physio_coach.yaml" in html
    assert "HR_rest" in html and f"{result.report['hr_rest']:.4g}" in html


def test_cli_on_the_bag_directory_writes_to_its_parent(tmp_path: Path, capsys) -> None:
    bag = Path(shutil.copytree(REAL_BAG, tmp_path / "bags" / REAL_BAG.name))
    assert main([str(bag), "--quiet", "--no-figures"]) == 0
    out = tmp_path / "bags"
    assert {p.name for p in out.iterdir()} == {"report.json", "report.html", REAL_BAG.name}
    report = json.loads((out / "report.json").read_text())
    assert report["hr_topic_from"] == "coach log (/rosout)"  # no configs/ here: the coach's own log line
    assert capsys.readouterr().err == ""
