"""The whole 23-minute exercise session on a fake clock (no ROS): sequence, timing, faults."""

from __future__ import annotations

import itertools
import json
import math
import time
from collections.abc import Callable
from typing import Any

import pytest

from hri_physio_coach.coach import ExerciseCoach, shipped_gesture_durations
from hri_physio_coach.config import CoachConfig
from qt_controller.emotions import EmotionCatalogue

CALIB, WARM, COND, COOL, END = 0.0, 180.0, 480.0, 1080.0, 1380.0
# (start, activity, gesture, video) of every activity of the thesis routine.
ACTIVITIES = [
    (180, "basic_marching", "marching"), (360, "step_up_reach_pull", "step_up"),
    (480, "marching", "marching"), (540, "lateral_knees", "lateral"), (660, "marching", "marching"),
    (720, "both_arms_forward", "arms_forward"), (840, "marching", "marching"),
    (900, "lateral_knees", "lateral"), (1020, "marching", "marching"),
    (1080, "step_up_reach_pull", "step_up"), (1200, "basic_marching", "marching"),
]

HrFn = Callable[[float, "ExerciseCoach"], float | None]


#: Media as in the thesis: one file per tempo (the packaged default names built-in sources instead).
THESIS_FILES = {"audio_path": "./audio/{}.wav", "video_path": "./video/{}.mp4",
                "audio_exercise_base": "exercise_{}"}


class Session:
    """Runs a coach on a fake clock, with one HR sample per second (at t + 0.5)."""

    def __init__(self, hr: HrFn, step: float = 1.0, send: Callable[[str], None] | None = None,
                 **config: Any) -> None:
        self.now = 0.0
        self.events: list[dict[str, Any]] = []
        self.commands: list[tuple[float, str]] = []
        self.hr = hr
        self.step = step
        cfg = CoachConfig(**{"part_age": 33.0, **THESIS_FILES, **config})

        def record(line: str) -> None:
            self.commands.append((self.coach.engine.now, line))
            if send is not None:
                send(line)

        self.coach = ExerciseCoach(cfg, lambda: self.now, record, self.events.append)

    def run(self, until: float | None = None) -> Session:
        if not self.coach.started:
            self.coach.start(0.0)
        next_sample = 0.5
        while not self.coach.finished and (until is None or self.now < until):
            self.now += self.step
            while next_sample <= self.now:
                value = self.hr(next_sample, self.coach)
                if value is not None:
                    self.coach.on_hr(value, now=next_sample)
                next_sample += 1.0
            self.coach.tick(self.now)
        return self

    def of(self, event: str, /, **match: Any) -> list[dict[str, Any]]:
        return [e for e in self.events
                if e["event"] == event and all(e.get(k) == v for k, v in match.items())]

    def times(self, event: str, /, **match: Any) -> list[float]:
        return [e["t"] for e in self.of(event, **match)]

    def sent(self, prefix: str) -> list[tuple[float, str]]:
        return [(t, c) for t, c in self.commands if c.startswith(prefix)]


def pilot_hr(t: float, coach: ExerciseCoach) -> float:
    """85.4 bpm seated; then a heart that follows the ladder (each step +6 bpm) and drifts up."""
    if t < WARM:
        return 85.4
    return 112.0 + 6.0 * coach.ladder.index + 0.02 * (t - WARM)


@pytest.fixture(scope="module")
def session() -> Session:
    started = time.perf_counter()
    s = Session(pilot_hr).run()
    s.wall = time.perf_counter() - started  # type: ignore[attr-defined]
    return s


def test_whole_routine_runs_on_a_fake_clock_without_waiting_in_real_time(session: Session) -> None:
    assert session.coach.engine.state == "finished"
    # The routine is 23 min of session time; idle it runs in a fraction of a second (1.06 s seen on a
    # busy machine): a bound far above that, and far below any real waiting, is not a timing test.
    assert session.wall < 30.0  # type: ignore[attr-defined]
    assert session.events[0]["event"] == "session_start" and session.events[0]["duration"] == END
    end = session.of("session_end")
    assert len(end) == 1 and end[0]["t"] == END


def test_phases_and_activities(session: Session) -> None:
    assert [(e["t"], e["phase"]) for e in session.of("phase")] == [
        (CALIB, "calibration"), (WARM, "warm_up"), (COND, "conditioning"), (COOL, "cool_down")]
    acts = [(e["t"], e["activity"], e.get("gesture")) for e in session.of("activity")]
    assert acts[0] == (0.0, "seated_rest", None)
    assert acts[1:] == [(float(t), name, gesture) for t, name, gesture in ACTIVITIES]
    durations = [e["duration"] for e in session.of("activity")]
    assert sum(durations) == END


def test_calibration_zone_and_announcement(session: Session) -> None:
    calib = session.of("calibration")
    assert len(calib) == 1 and calib[0]["t"] == WARM
    # The heart rate taken from calib_settle (15 s) after the start until the end.
    assert calib[0]["source"] == "measured" and calib[0]["n_samples"] == 165
    assert calib[0]["window"] == [15.0, WARM]
    assert calib[0]["hr_rest"] == pytest.approx(85.4)
    zone = session.of("zone")[0]
    assert zone["hr_max"] == pytest.approx(184.9)
    assert zone["low"] == pytest.approx(125.2, abs=0.051) and zone["high"] == pytest.approx(155.1, abs=0.051)
    announce = [c for t, c in session.sent("set speech") if t == WARM and "resting heart rate" in c]
    assert len(announce) == 1
    assert "85.4" in announce[0] and "125.2" in announce[0] and "155.1" in announce[0]
    # Calibration: relaxing audio and video, base gesture at 0.5, reminders of breath and time left.
    at0 = [c for t, c in session.commands if t == 0.0]
    assert "set audio ./audio/relaxing.wav" in at0 and "set video ./video/relaxing.mp4" in at0
    assert "set gesture base 0.50" in at0
    reminders = [(t, c) for t, c in session.sent("set speech") if "breathe" in c]
    assert reminders == [
        (60.0, "set speech You're doing great. Don't forget to breathe. Only 2 minutes left."),
        (120.0, "set speech You're doing great. Don't forget to breathe. Only 1 minute left."),
    ]


def test_every_activity_video_then_splash_gesture_music_and_instruction(session: Session) -> None:
    for start, _name, gesture in ACTIVITIES:
        at_start = [c for t, c in session.commands if t == start]
        assert f"set video ./video/{gesture}.mp4" in at_start
        assert "set speech Try to imitate the video, while keeping pace with the music" in at_start
        gestures = [c for c in at_start if c.startswith(f"set gesture {gesture} ")]
        assert gestures, (start, at_start)
        musics = [c for c in at_start if c.startswith("set audio ./audio/exercise_")]
        assert musics
        # The splash screen comes 30 s later, and no other video in between.
        videos = [(t, c) for t, c in session.sent("set video") if start < t <= start + 30]
        assert videos == [(start + 30.0, "set video ./video/splash.mp4")]


def test_gesture_speed_and_music_tempo_follow_the_ladder(session: Session) -> None:
    speeds = {0.90: "110", 0.95: "115", 1.00: "120", 1.05: "125", 1.10: "130", 1.15: "135"}
    gestures = [(t, float(c.split()[-1])) for t, c in session.sent("set gesture") if "base" not in c]
    audios = session.sent("set audio ./audio/exercise_")
    for t, speed in gestures:  # every play, repetitions too, at the tempo of the music playing then
        playing = [c for ta, c in audios if ta <= t][-1]
        assert playing == f"set audio ./audio/exercise_{speeds[round(speed, 2)]}.wav"
    assert gestures[0] == (WARM, 0.95)  # speed_idx 1


def test_the_activity_gesture_repeats_for_the_whole_activity_at_the_current_speed(session: Session) -> None:
    durations = shipped_gesture_durations()
    ends = [float(start) for start, _, _ in ACTIVITIES[1:]] + [END]
    for (start, _, gesture), end in zip(ACTIVITIES, ends, strict=True):
        plays = [(t, float(c.split()[-1])) for t, c in session.sent("set gesture ") if start <= t < end]
        assert all(c.startswith(f"set gesture {gesture} ") for t, c in session.sent("set gesture ")
                   if start <= t < end)
        assert plays[0][0] == start
        # Each play starts when the last one ends (or sooner, at a speed change), until the activity ends.
        for (t0, speed), (t1, _) in itertools.pairwise(plays):
            assert 0 < t1 - t0 <= durations[gesture] / speed + session.step
        assert end - plays[-1][0] <= durations[gesture] / plays[-1][1] + session.step
        longest = durations[gesture] / min(s for _, s in plays) + session.step  # ticks come every step
        assert len(plays) >= (end - start) / longest - 1
    # Calibration's gesture (a fixed speed) plays once; nothing is repeated after the session.
    assert [t for t, c in session.sent("set gesture base")] == [0.0]
    assert not [t for t, _ in session.sent("set gesture") if t >= END]


def test_calibration_shows_encouraging_faces_in_turn(session: Session) -> None:
    faces = session.of("behaviour", kind="encouragement")
    assert [e["t"] for e in faces] == [45.0, 90.0, 135.0]  # every calib_face_period while seated
    assert [e["emotion"] for e in faces] == ["showing_smile", "happy_blinking", "happy"]
    robot_faces = EmotionCatalogue()  # QT's standard set: the default faces need no extra expression files
    assert all(robot_faces.resolve(e) for e in CoachConfig().emotion_calibration)
    for e in faces:
        assert (e["t"], f"set emotion {e['emotion']}") in session.commands


def test_the_warm_up_opens_with_moving_the_chair_and_bringing_the_step(session: Session) -> None:
    said = [c for t, c in session.sent("set speech") if WARM <= t < WARM + 30]
    first = next(i for i, c in enumerate(said) if "chair" in c)
    assert "stepping platform" in said[first]
    assert all("follow my lead" not in c for c in said[:first])


def test_gesture_repeat_can_be_off() -> None:
    off = Session(pilot_hr, gesture_repeat=False).run(until=WARM + 170)
    changes = [e["t"] for e in off.of("rule_update") if e["decision"]["changed"]]
    plays = [t for t, _ in off.sent("set gesture marching")]
    assert plays[0] == WARM and plays[1:] == changes  # at the activity's start and at a speed change only
    assert not off.of("command", why="gesture repeat")


def test_behaviours_every_20_s_and_rule_updates_every_30_s(session: Session) -> None:
    rules = session.times("rule_update")
    assert rules == [WARM + 30.0 * k for k in range(1, 40)]  # 210 ... 1350
    behaviours = [e["t"] for e in session.of("behaviour") if e["kind"] not in ("reminder", "encouragement")]
    slots = [WARM + 20.0 * k for k in range(1, 60)]  # 200 ... 1360
    assert behaviours == [t for t in slots if t not in rules]
    assert session.times("hook_skipped") == [t for t in slots if t in rules]  # the rule update wins
    kinds = {e["kind"] for e in session.of("behaviour")}
    assert kinds == {"motivation", "emotion", "hr_report", "reminder", "encouragement"}
    for e in session.of("behaviour", kind="hr_report"):
        spoken = float(e["text"].split()[-4])  # "... was 131 beats per minute."
        assert "beats per minute" in e["text"] and e["hr"] == pytest.approx(spoken, abs=0.5)
    for e in session.of("behaviour", kind="emotion"):
        assert (e["t"], "set emotion happy") in session.commands


def test_rule_updates_use_and_clear_the_buffer(session: Session) -> None:
    for e in session.of("rule_update"):
        # One sample per second: 30 per update (fewer right after an activity start clears it).
        assert e["inputs"]["n_valid"] in (30,), e
        decision = e["decision"]
        assert decision["index_after"] - decision["index_before"] == decision["delta"]
    first = session.of("rule_update")[0]
    assert first["inputs"]["hr_mean"] == pytest.approx(112.0 + 6.0 + 0.02 * 15.0)  # mean of 180.5..209.5
    assert first["decision"]["action"] == "speed_up"


def test_thesis_like_adaptation_pattern(session: Session) -> None:
    actions = [(e["inputs"]["phase"], e["decision"]["action"]) for e in session.of("rule_update")]
    ups = [p for p, a in actions if a == "speed_up"]
    assert ups and set(ups) == {"warm_up"}  # speed-ups early, none later
    assert all(a in ("encourage", "slow_down", "at_limit") for p, a in actions if p != "warm_up")
    # Each adaptation is announced, the gesture and music re-sent at the new pace.
    for e in session.of("rule_update"):
        t, action = e["t"], e["decision"]["action"]
        said = [c for tt, c in session.sent("set speech") if tt == t]
        if action == "speed_up":
            assert "set speech Let's pick up the pace!" in said
            assert any(c.startswith("set gesture") for tt, c in session.commands if tt == t)
        elif action == "slow_down":
            assert "set speech Let's slow down a little, don't over-exert yourself." in said


def test_end_congratulates_and_thanks(session: Session) -> None:
    final = [c for t, c in session.commands if t == END]
    assert any("Congratulations" in c and "Thank you" in c for c in final)
    assert "set emotion happy" in final
    summary = session.of("summary")[0]
    assert summary["decisions"] == 39


def test_participant_id_everywhere_and_never_the_name() -> None:
    s = Session(pilot_hr, part_name="Alice Example", address_by_name=True).run()
    pid = s.coach.participant
    assert all(e["participant"] == pid for e in s.events)
    assert any("Alice Example" in c for _, c in s.commands)  # the robot does say it ...
    assert "Alice" not in json.dumps(s.events)  # ... but no event carries it
    quiet = Session(pilot_hr, part_name="Alice Example").run()
    assert not any("Alice" in c for _, c in quiet.commands)  # default: the robot does not say the name


def test_events_are_json_with_a_time() -> None:
    s = Session(pilot_hr).run(until=400)
    for e in s.events:
        assert isinstance(e["t"], float) and isinstance(e["event"], str)
        json.dumps(e, allow_nan=False)


def test_missing_hr_pauses_adaptation_and_resumes() -> None:
    def hr(t: float, coach: ExerciseCoach) -> float | None:
        if 600 <= t < 700:
            return None  # the strap lost contact
        return pilot_hr(t, coach)

    s = Session(hr).run()
    assert s.coach.engine.state == "finished"  # the routine went on
    lost, resumed = s.of("hr_lost"), s.of("hr_resumed")
    assert len(lost) == 1 and lost[0]["t"] == 610.0 and lost[0]["silent_since"] == 599.5
    assert len(resumed) == 1 and resumed[0]["t"] == 700.5
    gated = [e for e in s.of("rule_update") if e["decision"]["action"] == "gated"]
    assert [e["t"] for e in gated] == [630.0, 660.0, 690.0]
    assert all("no heart-rate data" in e["decision"]["reason"] for e in gated)
    for e in gated:  # nothing about pace: no command on the rule's behalf
        assert not [c for c in s.of("command") if c["t"] == e["t"] and c["why"].startswith("rule update")]
    assert [c for c in s.of("command") if c["why"].startswith("rule update") and c["t"] == 720.0]
    assert s.times("activity")[-5:] == [840.0, 900.0, 1020.0, 1080.0, 1200.0]
    after = next(e for e in s.of("rule_update") if e["t"] == 720.0)
    assert after["decision"]["action"] != "gated" and after["inputs"]["n_valid"] == 20


@pytest.mark.parametrize(
    "bad,reason",
    [
        (lambda t: float("nan"), "too few valid HR samples: 0 < 10"),
        (lambda t: 20.0 if int(t) % 5 else 140.0, "too few valid HR samples: 6 < 10"),  # implausible
        (lambda t: 250.0 if int(t) % 3 else 140.0, "signal flagged: 20 of 30 samples invalid or flagged"),
    ],
    ids=["nan", "too-low", "too-high"],
)
def test_bad_signal_gates_adaptation(bad: Callable[[float], float], reason: str) -> None:
    def hr(t: float, coach: ExerciseCoach) -> float:
        return bad(t) if 480 <= t < 540 else pilot_hr(t, coach)

    s = Session(hr).run(until=560)
    gated = {e["t"]: e["decision"]["reason"] for e in s.of("rule_update")
             if e["decision"]["action"] == "gated"}
    assert set(gated) == {510.0, 540.0}
    assert all(reason in r for r in gated.values())


def test_flagged_signal_gates_adaptation() -> None:
    s = Session(pilot_hr).run(until=480)
    coach = s.coach
    for i in range(30):  # two thirds of the samples flagged by the source
        coach.on_hr(120.0, now=480.5 + i, flagged=i % 3 != 0)
    coach.tick(510.0)
    e = s.of("rule_update")[-1]
    assert e["t"] == 510.0 and e["decision"]["action"] == "gated"
    assert e["decision"]["reason"] == "signal flagged: 20 of 30 samples invalid or flagged (> 50%)"
    assert (e["inputs"]["n_valid"], e["inputs"]["n_flagged"]) == (10, 20)
    for i in range(30):
        coach.on_hr(120.0, now=510.5 + i, flagged=i % 10 == 0)  # 3 of 30 flagged: fine
    coach.tick(540.0)
    assert s.of("rule_update")[-1]["decision"]["action"] != "gated"
    s2 = Session(pilot_hr, min_valid_samples=5, max_invalid_fraction=0.2).run(until=480)
    for i in range(30):
        s2.coach.on_hr(120.0, now=480.5 + i, flagged=i % 2 == 0)
    s2.coach.tick(510.0)
    assert "signal flagged: 15 of 30 samples" in s2.of("rule_update")[-1]["decision"]["reason"]


def test_robot_command_failures_are_logged_and_do_not_stop_the_session() -> None:
    def send(line: str) -> None:
        if line.startswith("set gesture"):
            raise ConnectionError("robot unreachable")

    s = Session(pilot_hr, send=send).run()
    assert s.coach.engine.state == "finished"
    failed = s.of("command_failed")
    assert failed and all(e["command"].startswith("set gesture") for e in failed)
    assert "ConnectionError: robot unreachable" in failed[0]["message"]
    s.coach.on_reply({"t": 1.0, "ok": False, "command": "set emotion grumpy", "message": "unknown emotion"})
    assert s.of("command_failed")[-1]["source"] == "robot"


def test_calibration_skipped_uses_resting_default() -> None:
    s = Session(pilot_hr, calib_skip=True, resting_default=70.0).run()
    assert [e["phase"] for e in s.of("phase")] == ["warm_up", "conditioning", "cool_down"]
    assert s.of("session_end")[0]["t"] == 1200.0
    calib = s.of("calibration")[0]
    assert calib["source"] == "default" and calib["hr_rest"] == 70.0 and calib["t"] == 0.0
    zone = s.of("zone")[0]
    assert zone["low"] == pytest.approx(70 + 0.4 * (184.9 - 70))


def test_calibration_without_hr_falls_back_to_resting_default() -> None:
    s = Session(lambda t, c: None if t < WARM else 120.0).run(until=200)
    calib = s.of("calibration")[0]
    assert calib["source"] == "default" and calib["hr_rest"] == 61.0
    assert "too few valid HR samples during calibration: 0 < 30" in calib["reason"]


@pytest.mark.parametrize("policy", ["threshold", "fuzzy", "static"])
def test_policies_by_name_through_the_coach(policy: str) -> None:
    s = Session(lambda t, c: 85.4 if t < WARM else 100.0, policy=policy).run()
    idx = [e["decision"]["index_after"] for e in s.of("rule_update")]
    if policy == "static":
        assert set(idx) == {1}
    else:
        assert max(idx) == 5  # far below the zone: up to the top of the ladder, never beyond
    assert all(e["decision"]["policy"] == policy for e in s.of("rule_update"))


def test_thesis_fixes_through_the_coach() -> None:
    s = Session(lambda t, c: 85.4 if t < WARM else 100.0, adapt_conditioning_only=True,
                adapt_cooldown_schedule=True, adapt_refractory=True).run()
    by_phase: dict[str, list[dict]] = {}
    for e in s.of("rule_update"):
        by_phase.setdefault(e["inputs"]["phase"], []).append(e["decision"])
    assert {d["action"] for d in by_phase["warm_up"]} == {"hold"}
    cond = [d["action"] for d in by_phase["conditioning"]]
    assert cond[:4] == ["speed_up", "hold", "speed_up", "hold"]  # 60 s refractory
    cool = by_phase["cool_down"]
    assert all(d["delta"] <= 0 for d in cool) and cool[-1]["index_after"] == 0
    said = [c for t, c in s.commands if t > COOL and "cool down" in c]
    assert said


def test_a_faster_clock_step_gives_the_same_session() -> None:
    fine = Session(pilot_hr, step=0.25).run()
    coarse = Session(pilot_hr, step=1.0).run()
    # A repeated gesture starts at the first tick after the last one ended: that depends on the step.
    def key(s: Session) -> list[tuple]:
        return [(e["t"], e["event"], e.get("activity"), e.get("kind")) for e in s.events
                if e.get("why") != "gesture repeat"]

    def commands(s: Session) -> list[str]:
        repeats = {(e["t"], e["command"]) for e in s.of("command", why="gesture repeat")}
        return [c for t, c in s.commands if (t, c) not in repeats]

    assert key(fine) == key(coarse)
    assert commands(fine) == commands(coarse)
    assert math.isclose(fine.of("zone")[0]["low"], coarse.of("zone")[0]["low"])


def test_activity_start_clears_the_buffer() -> None:
    # With 50-s rule updates (warm-up from 180 s: 230, 280, 330, 380 ...), the update at 380 s
    # sees only what came after the step-up activity started at 360 s.
    s = Session(pilot_hr, rule_period=50.0).run(until=400)
    n_valid = {e["t"]: e["inputs"]["n_valid"] for e in s.of("rule_update")}
    assert n_valid == {230.0: 50, 280.0: 50, 330.0: 50, 380.0: 20}


def test_commands_a_controller_never_answers_are_recorded_once_and_not_sent_again() -> None:
    """Replies come, then the controller is down (a restart) for 60 s: each command sent meanwhile
    is one command_unanswered event after reply_timeout; answered ones never are."""
    session: Session

    def send(line: str) -> None:
        now = session.coach.engine.now
        if not 400.0 <= now < 460.0:  # the controller's outage
            session.coach.on_reply({"ok": True, "command": line, "message": "done"})

    session = Session(lambda t, c: 140.0, send=send, reply_timeout=20.0)
    session.run()
    lost = [(t, c) for t, c in session.commands if 400.0 <= t < 460.0]
    unanswered = session.of("command_unanswered")
    assert lost and [(e["sent_t"], e["command"]) for e in unanswered] == lost
    assert all(20.0 < e["waited"] <= 21.0 and e["t"] == pytest.approx(e["sent_t"] + e["waited"])
               for e in unanswered)
    assert len(session.commands) == len(session.of("command"))  # nothing was sent twice


def test_without_any_reply_nothing_is_awaited() -> None:
    """The offline evaluation drives the coach with no controller: no reply is expected."""
    session = Session(lambda t, c: 140.0, reply_timeout=5.0).run()
    assert session.commands and not session.of("command_unanswered")
