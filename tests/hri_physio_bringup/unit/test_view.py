"""The session launcher's view: what it makes of the coach's events and the heart rate."""

from __future__ import annotations

import math

import pytest

from hri_physio_bringup.view import (
    BAD_FIELDS,
    NO_EVENT,
    NOT_JSON,
    NOT_OBJECT,
    SessionView,
    session_counts,
    summary,
)
from hri_physio_coach import gates


def test_view_counts_adaptations_gated_updates_and_time_in_zone() -> None:
    view = SessionView()
    view.on_hr(85.0, 9.0, 9.0)  # before the session: seen, not counted
    view.on_event({"t": 10.0, "event": "session_start"})
    view.on_event({"t": 190.0, "event": "zone", "low": 125.0, "high": 155.0})
    view.state = {"phase": "warm_up", "phase_kind": "warm_up", "activity": "marching"}
    for i, bpm in enumerate((120.0, 130.0, 140.0, 160.0)):
        view.on_hr(bpm, 200.0 + i, 200.0 + i)
    view.on_event({"t": 220.0, "event": "rule_update", "decision": {"changed": True, "action": "speed_up"}})
    for n in (4, 6):
        view.on_event({"t": 250.0, "event": "rule_update",
                       "decision": {"changed": False, "action": "gated", "gate": gates.TOO_FEW_SAMPLES,
                                    "reason": f"too few valid HR samples: {n} < 10"}})
    view.on_event({"t": 280.0, "event": "rule_update",
                   "decision": {"changed": False, "action": "gated", "gate": gates.NO_HR_DATA,
                                "reason": "no heart-rate data for 12 s: adaptation paused"}})
    view.on_event({"t": 310.0, "event": "rule_update",
                   "decision": {"changed": False, "action": "hold", "gate": gates.REFRACTORY,
                                "reason": "refractory: 30 s since the last update < 60 s"}})
    view.on_event({"t": 1390.0, "event": "session_end"})
    assert (view.hr_seen, view.hr_samples, view.exercise_hr, view.exercise_in_zone) == (5, 4, 4, 2)
    # Grouped by the code the coach gives, whatever numbers the prose holds.
    assert view.adaptations == 1 and view.gated == {gates.TOO_FEW_SAMPLES: 2, gates.NO_HR_DATA: 1}
    assert view.held == {gates.REFRACTORY: 1}
    text = summary(view, wall=46.0, bag="bags/x")
    assert "23.0 min of session in 46 s wall (30x)" in text
    assert "50 % of 4 exercise HR samples in the zone; 1 adaptation in 5 rule updates" in text
    assert "2 rule update(s) gated: too few valid HR samples (too_few_samples)" in text
    assert "1 rule update(s) gated: no heart-rate data (adaptation paused) (no_hr_data)" in text
    assert "1 rule update(s) held: refractory period after the last adaptation (refractory)" in text
    assert "malformed" not in text
    assert "recorded to bags/x" in text
    assert "ended" in view.progress(1390.0)


def test_hr_samples_are_counted_by_sample_time_not_arrival() -> None:
    view = SessionView()
    lsl = 5000.0  # the strap's clock runs 5000 s ahead of sim time
    view.on_hr(80.0, lsl + 9.5, 9.5)  # sampled before the start (delivered at once)
    view.on_event({"t": 10.0, "event": "session_start"})
    view.on_hr(81.0, lsl + 9.9, 12.0)  # arrives (late) after the start event, sampled before it: not counted
    view.on_hr(82.0, lsl + 10.0, 12.0)
    assert view.hr_samples == 1
    view.on_event({"t": 20.0, "event": "session_end"})
    view.on_hr(83.0, lsl + 19.5, 21.0)  # arrives after the end event, sampled inside the session: counted
    view.on_hr(84.0, lsl + 20.0, math.nan)  # sampled at the end: not counted
    assert (view.hr_seen, view.hr_samples) == (5, 2)
    assert view.hr_clock_offset == pytest.approx(lsl)  # from the fastest value


def test_every_gate_code_has_a_label() -> None:
    codes = [v for k, v in vars(gates).items() if k.isupper() and isinstance(v, str)]
    assert sorted(codes) == sorted(gates.LABELS)
    assert gates.label("made_up") == "made_up"


def test_malformed_events_are_counted_and_logged_rate_limited() -> None:
    lines: list[str] = []
    wall = [0.0]
    view = SessionView(warn=lines.append, monotonic=lambda: wall[0])
    assert view.on_event_text('{"t": 10.0, "event": "session_start"}')
    bad = ["not json", "", "[1, 2]", "42", '"text"', '{"t": 1.0}', '{"event": ""}', '{"event": 7}',
           '{"event": "zone", "low": 120.0}', '{"event": "rule_update", "decision": "gated"}',
           '{"event": "session_end", "t": "soon"}', b"\xff\xfe"]
    assert not any(view.on_event_text(text) for text in bad)  # type: ignore[arg-type]
    assert view.malformed == {NOT_JSON: 3, NOT_OBJECT: 3, NO_EVENT: 3, BAD_FIELDS: 3}
    # Nothing half-applied: the session did not end, no zone, no rule update counted.
    assert view.ended_at is None and view.zone is None and view.events == {"session_start": 1}
    assert len(lines) == 4  # one line per kind, at once
    assert all("ignoring a message on the coach's events" in line for line in lines)
    for _ in range(100):
        view.on_event_text("{")
    assert len(lines) == 4  # a flood within the period: counted, not printed
    wall[0] += 60.0
    view.on_event_text("{")
    assert len(lines) == 5 and "103 such message(s) since the last report" in lines[-1]
    assert view.malformed[NOT_JSON] == 104
    assert view.on_event_text('{"t": 1390.0, "event": "session_end"}') and view.ended_at == 1390.0
    text = summary(view, wall=46.0, bag=None)
    assert ("113 malformed event message(s) ignored: 3 bad_fields, 3 no_event, 104 not_json, 3 not_object"
            in text)


def test_summary_of_a_session_stopped_before_its_end() -> None:
    view = SessionView()
    text = summary(view, wall=12.0, bag=None, now=5.0)
    assert "stopped before the session started, after 12 s wall" in text
    view.on_event({"t": 10.0, "event": "session_start"})
    text = summary(view, wall=255.0, bag=None, now=250.0)
    assert "[session] stopped before its end: 4.0 min of session in 255 s wall (1x)" in text


def test_the_straps_stalls_are_in_the_summary_and_its_counts() -> None:
    view = SessionView()
    assert session_counts(view)["polar_streamer"] is None and "polar_streamer" not in summary(view, 1.0, None)
    view.strap_status = {"state": "streaming", "stalls": 3, "stall_reconnects": 1, "reconnects": 2,
                         "streams": {"ecg": {"samples": 1000, "stalls": 3}}}
    assert session_counts(view)["polar_streamer"]["stalls"] == 3
    assert session_counts(view)["polar_streamer"]["streams"]["ecg"]["stalls"] == 3
    assert ("[session] polar_streamer: 3 stall(s) of a stream (1 ended in a reconnection), 2 reconnection(s) "
            "in all") in summary(view, 1.0, None)
