"""The calm console: which node lines it shows, the progress lines, the live display (no ROS)."""

from __future__ import annotations

import io
import math

import pytest

from hri_physio_bringup.console import (
    ERROR,
    WARNING,
    EchoFilter,
    LineClassifier,
    LiveConsole,
    PlainConsole,
    Progress,
    VerboseConsole,
)
from hri_physio_bringup.view import SessionView


@pytest.mark.parametrize("line,expected", [
    ("[INFO] [1795461155.512106971] [qt_physio_coach]: session ended", None),
    ("[WARN] [1795461155.5] [hr_receiver]: stream rate 500 Hz, configured 130 Hz",
     (WARNING, "stream rate 500 Hz, configured 130 Hz")),
    ("[ERROR] [1795461155.5] [qt_physio_coach]: stopped: another session",
     (ERROR, "stopped: another session")),
    ("[FATAL] [1.0] [x]: gone", (ERROR, "gone")),
    ("physio_receiver: error: sampling_rate: expected greater than 0", (ERROR, "sampling_rate: expected "
                                                                         "greater than 0")),
    ("hri_physio_report: warning: the bag was cut short", (WARNING, "the bag was cut short")),
    ("type 'start' to begin the session ('stop' ends it)", None),
    ("received 52317 samples, published 52273 in 4021 frames, gaps 0", None),
])
def test_warnings_and_errors_are_read_from_the_line(line: str, expected: tuple[str, str] | None) -> None:
    assert LineClassifier()(line) == expected


def test_a_traceback_is_one_error_line_its_exception() -> None:
    classify = LineClassifier()
    lines = ["Traceback (most recent call last):", '  File "x.py", line 3, in <module>', "    main()",
             "", "During handling of the above exception, another exception occurred:", "",
             "Traceback (most recent call last):", '  File "y.py", line 1', "ValueError: bad value",
             "[INFO] [1.0] [x]: after"]
    assert [r for r in map(classify, lines) if r] == [(ERROR, "crashed: ValueError: bad value")]


def test_a_keyboard_interrupt_in_a_starting_node_is_not_a_crash() -> None:
    """The launcher's SIGINT reached a node still importing: its traceback ends in KeyboardInterrupt."""
    classify = LineClassifier()
    lines = ["Traceback (most recent call last):", '  File "pydantic/main.py", line 9', "KeyboardInterrupt",
             "Traceback (most recent call last):", '  File "x.py", line 3', "KeyboardInterruptError: no"]
    assert [r for r in map(classify, lines) if r] == [(ERROR, "crashed: KeyboardInterruptError: no")]


def test_the_same_warning_is_echoed_a_few_times_then_left_to_the_log() -> None:
    echo = EchoFilter(max_repeats=2)
    shown = [echo("hr_receiver", f"[WARN] [1.0] [hr_receiver]: gap of {n} samples") for n in range(6)]
    assert shown[:2] == ["[hr_receiver] WARN: gap of 0 samples", "[hr_receiver] WARN: gap of 1 samples"]
    assert shown[2] is not None and "further repeats only in logs/hr_receiver.log" in shown[2]
    assert shown[3:] == [None, None, None]
    assert echo("ecg_receiver", "[WARN] [1.0] [ecg_receiver]: gap of 1 samples") is not None  # another node
    assert echo.seen[("hr_receiver", WARNING)] == 6


def test_a_node_in_trouble_is_echoed_a_bounded_number_of_lines() -> None:
    echo = EchoFilter(max_repeats=3, max_per_node=4)
    shown = [echo("neurokit_processor", f"[WARN] [1.0] [p]: problem kind {chr(97 + n)}") for n in range(8)]
    assert shown[:3] == [f"[neurokit_processor] WARN: problem kind {c}" for c in "abc"]
    assert shown[3] == ("[neurokit_processor] WARN: problem kind d (further warnings of neurokit_processor "
                        "only in logs/neurokit_processor.log)")
    assert shown[4:] == [None] * 4
    assert echo("qt_controller", "[ERROR] [1.0] [c]: broken") == "[qt_controller] ERROR: broken"


def view_at(phase: str | None, hr: float = 120.0) -> SessionView:
    view = SessionView()
    view.on_event({"t": 100.0, "event": "session_start", "duration": 270.0})
    view.on_event({"t": 160.0, "event": "zone", "low": 125.0, "high": 155.0})
    view.state = {"phase": phase, "activity": "marching", "ladder_speed": 0.95, "ladder_tempo": 115.0}
    view.on_hr(hr, 190.0, 190.0)
    return view


def test_progress_says_where_the_session_is() -> None:
    p = Progress.of(view_at("warm_up", 120.0), now=190.0, duration=999.0, factor=29.6)
    assert (p.elapsed, p.remaining, p.duration) == (90.0, 180.0, 270.0)  # the routine's, from session_start
    assert p.zone_state == "below zone 125-155" and p.where == "warm_up / marching"
    assert p.pace == "tempo 115 BPM, gesture speed 0.95"
    line = p.line()
    assert line.startswith("[session] 01:30/04:30 warm_up / marching") and "30x" in line
    assert Progress.of(view_at("warm_up", 140.0), 190.0, 270.0, None).zone_state == "in zone 125-155"
    assert Progress.of(view_at("warm_up", 160.0), 190.0, 270.0, None).zone_state == "above zone 125-155"
    nan = Progress.of(view_at("warm_up", math.nan), 190.0, 270.0, None)
    assert nan.zone_state == "zone 125-155" and "HR   -   bpm" in nan.line()


def test_plain_console_prints_one_progress_line_per_minute_of_session() -> None:
    out = io.StringIO()
    console = PlainConsole(out, every=60.0)
    view = view_at("calibration")
    console.progress(Progress.of(SessionView(), 0.0, 270.0, None))  # not started: nothing
    for now in range(100, 371, 5):  # the session from 0 to 270 s, a look every 5 s
        if now == 370:
            view.on_event({"t": 370.0, "event": "session_end"})
        console.progress(Progress.of(view, float(now), 270.0, 30.0))
    console.progress(Progress.of(view, 380.0, 270.0, 30.0))  # after the end: nothing more
    lines = out.getvalue().splitlines()
    assert [line.split()[1] for line in lines] == ["00:00/04:30", "01:00/04:30", "02:00/04:30", "03:00/04:30",
                                                   "04:00/04:30", "04:30/04:30"]
    assert "ended" in lines[-1]


def test_plain_console_shows_warnings_only_and_verbose_shows_everything() -> None:
    out = io.StringIO()
    plain = PlainConsole(out)
    for line in ("[INFO] [1.0] [x]: fine", "[WARN] [1.0] [x]: careful"):
        plain.node_line("qt_controller", line)
    assert out.getvalue().splitlines() == ["[qt_controller] WARN: careful"]
    out = io.StringIO()
    verbose = VerboseConsole(out)
    for line in ("[INFO] [1.0] [x]: fine", "[WARN] [1.0] [x]: careful"):
        verbose.node_line("qt_controller", line)
    assert out.getvalue().splitlines() == ["[qt_controller] [INFO] [1.0] [x]: fine",
                                           "[qt_controller] [WARN] [1.0] [x]: careful"]


def test_live_console_draws_the_display_and_prints_warnings_above_it() -> None:
    from rich.console import Console

    screen = io.StringIO()
    console = LiveConsole("HRI Physio session P-1", console=Console(file=screen, force_terminal=True,
                                                                   width=120, color_system=None))
    console.say("[session] system ready")
    console.node_line("hr_receiver", "[WARN] [1.0] [hr_receiver]: stream came back at 500 Hz")
    console.node_line("hr_receiver", "[INFO] [1.0] [hr_receiver]: fine")
    console.progress(Progress.of(view_at("conditioning", 140.0), 250.0, 270.0, 30.0))
    console._live.refresh()
    console.close()
    console.say("[session] done")
    text = screen.getvalue()
    for shown in ("[session] system ready", "[hr_receiver] WARN: stream came back at 500 Hz",
                  "conditioning / marching", "02:30 / 04:30", "in zone 125-155",
                  "tempo 115 BPM, gesture speed 0.95", "30.0x real time", "[session] done"):
        assert shown in text, shown
    assert "fine" not in text
    assert text.rindex("[session] done") > text.rindex("conditioning / marching")  # below the display
