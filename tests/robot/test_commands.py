"""The /QtController/input text protocol: every command, and every way to get one wrong."""

from __future__ import annotations

import pytest

from qt_controller import commands as c


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
