"""config/foxglove_layout.json: valid JSON in Foxglove's layout format, topics of this project only."""

from __future__ import annotations

import json
import re

import pytest

from helpers import SRC
from hri_physio_bridge import topics
from hri_physio_processing.features import HEART_SCALARS, SIGNAL_FEATURES

LAYOUT = SRC / "hri_physio_bringup" / "config" / "foxglove_layout.json"
SCRIPT_PREFIX = "/studio_script/"
#: Panel types this layout may use (Foxglove's built-in panel ids).
PANEL_TYPES = {"Plot", "StateTransitions", "RawMessages", "Image", "RosOut"}


@pytest.fixture(scope="module")
def layout() -> dict:
    return json.loads(LAYOUT.read_text(encoding="utf-8"))


def _project_topics() -> set[str]:
    names = {v for v in vars(topics).values() if isinstance(v, str) and v.startswith("/")}
    processor = {f"{raw}/{feature}" for raw in (topics.POLAR_H10_ECG,)
                 for feature in (*HEART_SCALARS, *SIGNAL_FEATURES["ecg"], "status")}
    return names | processor


def _mosaic_leaves(node) -> list[str]:
    if isinstance(node, str):
        return [node]
    assert set(node) >= {"first", "second", "direction"}, node
    assert node["direction"] in ("row", "column")
    assert 0 < node.get("splitPercentage", 50) < 100
    return _mosaic_leaves(node["first"]) + _mosaic_leaves(node["second"])


def _scripts(layout: dict) -> dict[str, tuple[list[str], str]]:
    """name -> (input topics, output topic) as each user script declares them."""
    out = {}
    for node in layout["userNodes"].values():
        code = node["sourceCode"]
        inputs = re.search(r"export const inputs = \[([^\]]*)\];", code)
        output = re.search(r'export const output = "([^"]+)";', code)
        assert inputs and output, node["name"]
        out[node["name"]] = (re.findall(r'"([^"]+)"', inputs.group(1)), output.group(1))
        assert "export default function script(" in code
    return out


def _topic_of(path: str) -> str:
    """The topic of a message path such as ``/physio/polar_h10/hr.data[1]`` (topics hold no '.')."""
    return re.split(r"[.\[{]", path, maxsplit=1)[0]


def _referenced(config: dict) -> list[str]:
    found = []
    for panel_id, cfg in config.items():
        for p in cfg.get("paths", []):
            found.append(_topic_of(p["value"]))
        if "topicPath" in cfg:
            found.append(_topic_of(cfg["topicPath"]))
        if "imageMode" in cfg:
            found.append(cfg["imageMode"]["imageTopic"])
        assert panel_id.split("!")[0] in PANEL_TYPES, panel_id
    return found


def test_layout_has_the_parts_of_a_foxglove_layout(layout: dict) -> None:
    assert set(layout) >= {"configById", "layout", "userNodes", "globalVariables", "playbackConfig"}
    leaves = _mosaic_leaves(layout["layout"])
    assert sorted(leaves) == sorted(layout["configById"]), "every panel placed once, nothing else placed"
    for node in layout["userNodes"].values():
        assert set(node) == {"name", "sourceCode"}


def test_every_topic_is_one_of_this_project(layout: dict) -> None:
    known = _project_topics()
    scripts = _scripts(layout)
    outputs = {out for _inputs, out in scripts.values()}
    for name, (inputs, output) in scripts.items():
        assert output.startswith(SCRIPT_PREFIX), name
        assert set(inputs) <= known, (name, inputs)
    for topic in _referenced(layout["configById"]):
        if topic.startswith(SCRIPT_PREFIX):
            assert topic in outputs, f"{topic} is produced by no user script"
        else:
            assert topic in known, f"{topic} is not a topic of hri_physio_bridge.topics or the processor"


def test_the_panels_the_issue_asks_for(layout: dict) -> None:
    config = layout["configById"]
    scripts = _scripts(layout)
    by_output = {out: inputs for inputs, out in scripts.values()}

    def sources(topic: str) -> set[str]:
        return set(by_output.get(topic, [topic]))

    plots = [cfg for pid, cfg in config.items() if pid.startswith("Plot!")]
    hr_plot = next(cfg for cfg in plots
                   if any(_topic_of(p["value"]) == topics.POLAR_H10_HR for p in cfg["paths"]))
    assert {p["value"].split(".", 1)[1] for p in hr_plot["paths"]} >= {"zone_low", "zone_high"}
    assert all(p["enabled"] for p in hr_plot["paths"] if "zone_" in p["value"] and "target" not in p["value"])
    used = set()
    for cfg in config.values():
        for topic in [*(_topic_of(p["value"]) for p in cfg.get("paths", [])),
                      *([_topic_of(cfg["topicPath"])] if "topicPath" in cfg else [])]:
            used |= sources(topic)
    assert {topics.POLAR_H10_ECG, topics.COACH_EVENTS, topics.COACH_STATE, topics.QT_COMMANDS} <= used
    images = [cfg for pid, cfg in config.items() if pid.startswith("Image!")]
    assert [cfg["imageMode"]["imageTopic"] for cfg in images] == [topics.VIDEO_PREVIEW]
    assert any(pid.startswith("RosOut!") for pid in config)


def test_the_live_view_serves_every_topic_the_layout_reads(layout: dict) -> None:
    """The same layout works on the live connection (hri_physio_session --live) as on the bag: every
    topic its panels and scripts read is a channel of the live view, of the same name."""
    from hri_physio_bringup.live import LIVE_TOPICS

    scripts = _scripts(layout)
    read = {topic for inputs, _out in scripts.values() for topic in inputs}
    read |= {topic for topic in _referenced(layout["configById"]) if not topic.startswith(SCRIPT_PREFIX)}
    assert read and read <= set(LIVE_TOPICS), sorted(read - set(LIVE_TOPICS))
