"""The live view's options and messages, and how a session plans it (no ROS, no server)."""

from __future__ import annotations

import math
import socket
from datetime import datetime
from pathlib import Path

import pytest

from hri_physio_bridge.config import ConfigError
from hri_physio_bringup.folder import SessionFolder
from hri_physio_bringup.live import (
    DEFAULT_LIVE,
    FRAME_SCHEMA,
    LIVE_TOPICS,
    TEXT_SCHEMA,
    Demand,
    LiveViewConfig,
    frame_message,
    log_level,
    parse_live,
    text_message,
)
from hri_physio_bringup.options import SessionConfig
from hri_physio_bringup.plan import ECG_RECEIVER, HR_RECEIVER, LIVE, RECORDER, ROLE_OF, plan_session
from hri_physio_bringup.session import build_parser, main
from hri_physio_bringup.supervision import RESTARTABLE


@pytest.mark.parametrize(("value", "expected"), [
    ("8765", ("127.0.0.1", 8765)),
    ("127.0.0.1:9000", ("127.0.0.1", 9000)),
    ("0.0.0.0:8765", ("0.0.0.0", 8765)),
    ("station.lab:8765", ("station.lab", 8765)),
    ("[::1]:8765", ("::1", 8765)),
])
def test_live_addresses(value: str, expected: tuple[str, int]) -> None:
    assert parse_live(value) == expected


@pytest.mark.parametrize("value", ["", "abc", "127.0.0.1:", ":8765", "127.0.0.1:0", "host:70000",
                                   "bad host:1", "127.0.0.1:87a"])
def test_bad_live_addresses_say_what_is_expected(value: str) -> None:
    with pytest.raises(ValueError, match=r"expected \[HOST:\]PORT"):
        parse_live(value)


def test_live_alone_serves_on_this_host_only_and_is_off_by_default() -> None:
    parser = build_parser()
    assert parser.parse_args([]).live is None
    assert SessionConfig().live_address is None
    assert parser.parse_args(["--live"]).live == DEFAULT_LIVE == "127.0.0.1:8765"
    assert parser.parse_args(["--live", "--speed", "20"]).live == DEFAULT_LIVE
    assert parser.parse_args(["--live", "0.0.0.0:9000"]).live == "0.0.0.0:9000"
    assert SessionConfig.from_mapping({"live": DEFAULT_LIVE}, "test").live_address == ("127.0.0.1", 8765)
    assert LiveViewConfig().host == "127.0.0.1"  # the node too, unless told otherwise
    help_text = " ".join(parser.format_help().split())
    assert "--live [[HOST:]PORT]" in help_text and "Foxglove" in help_text and "127.0.0.1:8765" in help_text


def test_a_bad_live_value_is_one_error_line(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--live", "99999"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["hri_physio_session: error: command line: live: expected [HOST:]PORT with a port from 1 "
                   "to 65535, e.g. 127.0.0.1:8765 (got '99999')"]
    with pytest.raises(ConfigError, match="host: expected"):
        LiveViewConfig.from_mapping({"host": "bad host"}, "test")


def test_a_taken_port_is_one_error_line_before_anything_starts(tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        assert main(["--live", str(port), "--out", str(tmp_path / "sessions")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"hri_physio_session: error: live: cannot serve on "
                                               f"127.0.0.1:{port}: "), err
    assert not (tmp_path / "sessions").exists()  # nothing started, no folder


def plan_of(tmp_path: Path, **options):
    opts = SessionConfig.from_mapping(options, "test")
    folder = SessionFolder.plan(tmp_path / "sessions", "P-1", datetime(2026, 5, 4, 10, 30))
    return plan_session(opts, folder, "SIMLIVE1")


def test_a_session_with_live_runs_the_live_view_on_the_station(tmp_path: Path) -> None:
    off = plan_of(tmp_path)
    assert LIVE not in [n.name for n in off.nodes]
    on = plan_of(tmp_path, live="127.0.0.1:9123")
    names = [n.name for n in on.nodes]
    assert names.index(RECORDER) < names.index(LIVE) < names.index(HR_RECEIVER)
    live = on.node(LIVE)
    assert (live.script, live.config.host, live.config.port) == ("live_view", "127.0.0.1", 9123)
    # Not on sim time: it would take every /clock message, watched or not (logged at wall time).
    assert "use_sim_time:=true" not in live.extra
    assert ROLE_OF[LIVE] == "station" and LIVE in RESTARTABLE
    # Nothing waits for it: it listens only while a viewer watches (the receivers' listeners are as without).
    for receiver in (HR_RECEIVER, ECG_RECEIVER):
        assert on.node(receiver).config.min_consumers == off.node(receiver).config.min_consumers


def test_messages_keep_the_bags_shape_and_json_has_no_nan() -> None:
    frame = frame_message([("samples", 2, 4), ("channels:t,hr", 2, 2)], 0, [1.0, 60.0, 2.0, math.nan])
    assert frame == {"layout": {"dim": [{"label": "samples", "size": 2, "stride": 4},
                                        {"label": "channels:t,hr", "size": 2, "stride": 2}],
                                "data_offset": 0},
                     "data": [1.0, 60.0, 2.0, None]}
    assert set(FRAME_SCHEMA["required"]) == set(frame) and FRAME_SCHEMA["type"] == "object"
    assert text_message('{"t": 1}') == {"data": '{"t": 1}'} and TEXT_SCHEMA["required"] == ["data"]
    assert [log_level(level) for level in (10, 20, 30, 40, 50, 7)] == [1, 2, 3, 4, 5, 0]
    assert all(topic.startswith("/") for topic in LIVE_TOPICS)


def test_topics_are_subscribed_to_while_a_viewer_watches_them() -> None:
    demand = Demand()
    assert demand.changes(set()) == (set(), set())  # no viewer: no subscription
    demand.subscribe("/coach/state", client=1)
    demand.subscribe("/coach/state", client=2)
    demand.subscribe("/physio/polar_h10/hr", client=2)
    assert demand.changes(set()) == ({"/coach/state", "/physio/polar_h10/hr"}, set())
    held = {"/coach/state", "/physio/polar_h10/hr"}
    demand.unsubscribe("/coach/state", client=1)  # the other client still watches it
    demand.unsubscribe("/physio/polar_h10/hr", client=2)
    assert demand.changes(held) == (set(), {"/physio/polar_h10/hr"})
    demand.unsubscribe("/coach/state", client=2)
    demand.unsubscribe("/coach/state", client=3)  # a client that never subscribed: nothing
    assert demand.changes({"/coach/state"}) == (set(), {"/coach/state"})
