"""The /QtController/input text protocol: every command, and every way to get one wrong."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from qt_controller import commands as c
from qt_controller.joint_limits import PARTS


@pytest.mark.parametrize(
    "line,expected",
    [
        ("set speech Hello, let's march!", c.SetSpeech("Hello, let's march!")),
        ("SET SPEECH Keep  Going", c.SetSpeech("Keep  Going")),  # words kept as typed
        ("  set speech   padded text  ", c.SetSpeech("padded text")),
        ("set speechconfig 140 80", c.SetSpeechConfig(140, 80)),
        ("set speechConfig 150 90", c.SetSpeechConfig(150, 90)),  # the seed's spelling now works
        ("set SPEECH_CONFIG 50 200", c.SetSpeechConfig(50, 200)),
        ("set emotion happy", c.SetEmotion("happy")),
        ("set emotion QT/sad", c.SetEmotion("QT/sad")),
        ("set gesture marching 1.05", c.SetGesture("marching", 1.05)),
        ("set gesture step_up", c.SetGesture("step_up", 1.0)),
        ("set gesture lateral 0.1", c.SetGesture("lateral", 0.1)),
        ("set audio music/Calm Song.wav", c.SetAudio("music/Calm Song.wav")),
        ("set video intro.mp4", c.SetVideo("intro.mp4")),
        ("set volume 0", c.SetVolume(0)),
        ("set volume 100", c.SetVolume(100)),
        ("set state head 10 -5.5", c.SetState("head", (10.0, -5.5))),
        ("set state leftArm 90 -60 -30", c.SetState("leftarm", (90.0, -60.0, -30.0))),
        ("set state right_arm -90 -60 -30", c.SetState("rightarm", (-90.0, -60.0, -30.0))),
        ("set velocity head 75", c.SetVelocity("head", 75.0)),
        ("set vibration 50 1.5", c.SetVibration(50, 1.5)),
        ("set lights 255 0 10", c.SetLights(255, 0, 10)),
        ("get state rightarm", c.GetState("rightarm")),
        ("GET STATE Head", c.GetState("head")),
        ("get velocity leftarm", c.GetVelocity("leftarm")),
        ("get emotion", c.GetEmotion()),
        ("help", c.Help()),
        ("HELP", c.Help()),
        ("exit", c.Exit()),
        ("quit", c.Exit()),
    ],
)
def test_valid_commands_parse(line: str, expected: c.Command) -> None:
    assert c.parse_command(line) == expected


@pytest.mark.parametrize(
    "line,fragment",
    [
        ("", "empty command"),
        ("   ", "empty command"),
        ("dance", "unknown command 'dance'"),
        ("set", "'set' needs what to set"),
        ("get", "'get' needs what to get"),
        ("set colour red", "cannot set 'colour'"),
        ("get speech", "cannot get 'speech'"),
        ("set speech", "needs the text"),
        ("set speech    ", "needs the text"),
        ("set speechconfig 140", "takes 2 argument(s), got 1"),
        ("set speechconfig 140 80 1", "takes 2 argument(s), got 3"),
        ("set speechconfig high 80", "speech pitch must be a whole number"),
        ("set speechconfig 140 8.5", "speech speed must be a whole number"),
        ("set speechconfig 10 80", "speech pitch 10 is out of range"),
        ("set speechconfig 140 500", "speech speed 500 is out of range"),
        ("set emotion", "takes 1 argument(s), got 0"),
        ("set emotion very happy", "takes 1 argument(s), got 2"),
        ("set gesture", "takes 1 or 2 argument(s), got 0"),
        ("set gesture marching 1 2", "takes 1 or 2 argument(s), got 3"),
        ("set gesture marching fast", "gesture speed must be a number"),
        ("set gesture marching 0", "gesture speed 0 is out of range"),
        ("set gesture marching -1", "out of range"),
        ("set gesture marching nan", "must be a finite number"),
        ("set gesture marching inf", "must be a finite number"),
        ("set gesture marching 9", "out of range"),
        ("set audio", "needs a file name"),
        ("set video", "needs a file name"),
        ("set volume", "takes 1 argument(s), got 0"),
        ("set volume 50 60", "takes 1 argument(s), got 2"),
        ("set volume loud", "volume must be a whole number"),
        ("set volume 50.5", "volume must be a whole number"),
        ("set volume 101", "volume 101 is out of range [0, 100]"),
        ("set volume -1", "volume -1 is out of range"),
        ("set state", "needs a part"),
        ("set state tail 1 2", "unknown part 'tail'"),
        ("set state head 10", "takes 2 angle(s)"),
        ("set state head 10 20 30", "takes 2 angle(s)"),
        ("set state leftarm 1 2", "takes 3 angle(s)"),
        ("set state head ten 0", "HeadYaw must be a number"),
        ("set state head 0 nan", "HeadPitch must be a finite number"),
        ("set velocity head", "takes 2 argument(s), got 1"),
        ("set velocity neck 50", "unknown part 'neck'"),
        ("set velocity head 0", "velocity 0 is out of range"),
        ("set velocity head 101", "out of range"),
        ("set vibration 50", "takes 2 argument(s)"),
        ("set vibration 500 1", "vibration intensity 500 is out of range"),
        ("set vibration 50 0", "vibration seconds 0 is out of range"),
        ("set lights 1 2", "takes 3 argument(s)"),
        ("set lights 1 2 256", "blue 256 is out of range"),
        ("get state", "takes 1 argument(s), got 0"),
        ("get state head arms", "takes 1 argument(s), got 2"),
        ("get state knee", "unknown part 'knee'"),
        ("get velocity", "takes 1 argument(s)"),
        ("get emotion now", "takes 0 argument(s), got 1"),
        ("exit now", "takes 0 argument(s), got 1"),
        ("help me", "takes 0 argument(s), got 1"),
        ("set velocity head abc", "velocity must be a number, got 'abc'"),
        ("set lights a b c", "red must be a whole number, got 'a'"),
        ("set vibration x 1", "intensity must be a whole number, got 'x'"),
    ],
)
def test_malformed_commands_raise_clear_errors(line: str, fragment: str) -> None:
    with pytest.raises(c.ParseError) as info:
        c.parse_command(line)
    assert fragment in str(info.value)


def test_non_text_is_a_parse_error() -> None:
    with pytest.raises(c.ParseError, match="a command is text"):
        c.parse_command(None)  # type: ignore[arg-type]


def test_every_command_type_has_a_name_and_is_in_help() -> None:
    for kind, name in c._NAMES.items():
        assert c.command_name(kind.__new__(kind)) == name
        assert name.split()[-1] in c.HELP_TEXT


# --- typed commands to lines: to_line() is parse_command()'s inverse ------------------------------
def test_every_command_type_writes_itself_as_a_line() -> None:
    for kind in c._NAMES:
        assert callable(getattr(kind, "to_line", None)), kind.__name__


@pytest.mark.parametrize(
    "command,line",
    [
        (c.SetSpeech("Hello, let's march!"), "set speech Hello, let's march!"),
        (c.SetSpeechConfig(140, 80), "set speechconfig 140 80"),
        (c.SetEmotion("QT/happy"), "set emotion QT/happy"),
        (c.SetGesture("marching", 0.95), "set gesture marching 0.95"),
        (c.SetGesture("base", 0.5), "set gesture base 0.50"),  # the coach's wire format, as before
        (c.SetGesture("step_up", 1.0 / 3.0), f"set gesture step_up {1.0 / 3.0!r}"),  # exact, not rounded
        (c.SetAudio("./audio/exercise_125.wav"), "set audio ./audio/exercise_125.wav"),
        (c.SetVideo("music/Calm Song.mp4"), "set video music/Calm Song.mp4"),
        (c.SetVolume(60), "set volume 60"),
        (c.SetState("head", (10.0, -5.5)), "set state head 10.00 -5.50"),
        (c.SetVelocity("leftarm", 75.0), "set velocity leftarm 75.00"),
        (c.SetVibration(50, 1.5), "set vibration 50 1.50"),
        (c.SetLights(255, 0, 10), "set lights 255 0 10"),
        (c.GetState("rightarm"), "get state rightarm"),
        (c.GetVelocity("head"), "get velocity head"),
        (c.GetEmotion(), "get emotion"),
        (c.Help(), "help"),
        (c.Exit(), "exit"),
    ],
)
def test_to_line(command: c.Command, line: str) -> None:
    assert command.to_line() == line
    assert c.parse_command(line) == command


@pytest.mark.parametrize(
    "command,fragment",
    [
        (c.SetSpeech(""), "needs the text"),
        (c.SetSpeech("  padded "), "reads back as"),  # the protocol strips the text
        (c.SetEmotion("very happy"), "takes 1 argument(s)"),
        (c.SetGesture("marching", 9.0), "out of range"),
        (c.SetGesture("marching", float("nan")), "finite"),
        (c.SetGesture("two words", 1.0), "takes 1 or 2 argument(s)"),
        (c.SetVolume(101), "out of range"),
        (c.SetState("head", (1.0,)), "takes 2 angle(s)"),
        (c.SetState("tail", (1.0, 2.0)), "unknown part 'tail'"),
        (c.GetState("left_arm"), "reads back as"),  # not the canonical part name
        (c.SetAudio(""), "needs a file name"),
    ],
)
def test_to_line_refuses_what_the_protocol_cannot_carry(command: c.Command, fragment: str) -> None:
    with pytest.raises(c.ParseError) as info:
        command.to_line()
    assert fragment in str(info.value)


def _word() -> st.SearchStrategy[str]:
    return st.text(st.characters(blacklist_categories=("Cs",)), min_size=1, max_size=20).filter(
        lambda w: len(w.split()) == 1 and w == w.strip())


def _text() -> st.SearchStrategy[str]:
    return st.text(st.characters(blacklist_categories=("Cs",)), min_size=1, max_size=60).map(
        str.strip).filter(bool)


def _number(lo: float, hi: float) -> st.SearchStrategy[float]:
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


_PARTS = st.sampled_from(sorted(PARTS))
_COMMANDS = st.one_of(
    st.builds(c.SetSpeech, _text()),
    st.builds(c.SetSpeechConfig, st.integers(*c.SPEECH_PITCH_RANGE), st.integers(*c.SPEECH_SPEED_RANGE)),
    st.builds(c.SetEmotion, _word()),
    st.builds(c.SetGesture, _word(), _number(*c.GESTURE_SPEED_RANGE)),
    st.builds(c.SetAudio, _text()),
    st.builds(c.SetVideo, _text()),
    st.builds(c.SetVolume, st.integers(*c.VOLUME_RANGE)),
    _PARTS.flatmap(lambda part: st.builds(
        c.SetState, st.just(part), st.tuples(*[_number(-1e6, 1e6) for _ in PARTS[part]]))),
    st.builds(c.SetVelocity, _PARTS, _number(*c.VELOCITY_RANGE)),
    st.builds(c.SetVibration, st.integers(*c.VIBRATION_RANGE), _number(*c.VIBRATION_SECONDS_RANGE)),
    st.builds(c.SetLights, *[st.integers(*c.LIGHT_RANGE)] * 3),
    st.builds(c.GetState, _PARTS),
    st.builds(c.GetVelocity, _PARTS),
    st.just(c.GetEmotion()), st.just(c.Help()), st.just(c.Exit()),
)


@settings(max_examples=400, deadline=None)
@given(_COMMANDS)
def test_round_trip_command_line_command(command: c.Command) -> None:
    line = command.to_line()
    assert c.parse_command(line) == command
    assert c.command_name(command) == " ".join(line.split()[:2 if line.startswith(("set", "get")) else 1])


@settings(max_examples=300, deadline=None)
@given(_COMMANDS)
def test_round_trip_line_command_line(command: c.Command) -> None:
    """A parsed line writes back as the canonical line of the same command."""
    canonical = command.to_line()
    assert c.parse_command(canonical).to_line() == canonical
