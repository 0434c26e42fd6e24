"""The text command protocol of /QtController/input: typed commands to lines and back.

:func:`parse_command` reads a line into a command dataclass; every dataclass writes itself
back with ``to_line()``, so whoever sends commands (the coach) builds them typed and the two
directions cannot drift: ``parse_command(c.to_line()) == c`` for every valid command, and
``to_line()`` raises :class:`ParseError` for a command the protocol cannot carry (a gesture
speed out of range, a name with spaces, ...).

Command words and keys are case-insensitive (``set speechConfig 140 80`` works: the seed
lower-cased the line and then compared it with "speechConfig", so that command never
matched); arguments keep their case (speech text, file names, gesture names).
Anything malformed raises :class:`ParseError` with a message that says what was wrong.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from qt_controller.joint_limits import PARTS, JointLimitError, canonical_part

# Ranges the parser enforces (the robot may refuse more, e.g. joint limits).
VOLUME_RANGE = (0, 100)
SPEECH_PITCH_RANGE = (50, 200)
SPEECH_SPEED_RANGE = (20, 200)
GESTURE_SPEED_RANGE = (0.1, 4.0)
VELOCITY_RANGE = (1.0, 100.0)
VIBRATION_RANGE = (0, 100)
VIBRATION_SECONDS_RANGE = (0.05, 60.0)
LIGHT_RANGE = (0, 255)


class ParseError(ValueError):
    """A command line that is not a valid command; the message says why."""


def _num(value: float, decimals: int = 2) -> str:
    """A number as a short line token (``0.95``, ``0.50``) that reads back as exactly ``value``."""
    text = f"{value:.{decimals}f}"
    return text if float(text) == value else repr(float(value))


def _checked(command: object, line: str) -> str:
    """``line`` if it reads back as ``command``; :class:`ParseError` otherwise."""
    try:
        back = parse_command(line)
    except ParseError as exc:
        raise ParseError(f"{command!r} cannot be sent as a command line: {exc}") from None
    if back != command:
        raise ParseError(f"{command!r} cannot be sent as a command line: {line!r} reads back as {back!r}")
    return line


@dataclass(frozen=True)
class SetSpeech:
    text: str

    def to_line(self) -> str:
        return _checked(self, f"set speech {self.text}")


@dataclass(frozen=True)
class SetSpeechConfig:
    pitch: int
    speed: int

    def to_line(self) -> str:
        return _checked(self, f"set speechconfig {self.pitch} {self.speed}")


@dataclass(frozen=True)
class SetEmotion:
    name: str

    def to_line(self) -> str:
        return _checked(self, f"set emotion {self.name}")


@dataclass(frozen=True)
class SetGesture:
    name: str
    speed: float = 1.0

    def to_line(self) -> str:
        return _checked(self, f"set gesture {self.name} {_num(self.speed)}")


@dataclass(frozen=True)
class SetAudio:
    file: str

    def to_line(self) -> str:
        return _checked(self, f"set audio {self.file}")


@dataclass(frozen=True)
class SetVideo:
    file: str

    def to_line(self) -> str:
        return _checked(self, f"set video {self.file}")


@dataclass(frozen=True)
class SetVolume:
    percent: int

    def to_line(self) -> str:
        return _checked(self, f"set volume {self.percent}")


@dataclass(frozen=True)
class SetState:
    part: str
    degrees: tuple[float, ...]

    def to_line(self) -> str:
        return _checked(self, " ".join(["set state", self.part, *(_num(d) for d in self.degrees)]))


@dataclass(frozen=True)
class SetVelocity:
    part: str
    percent: float

    def to_line(self) -> str:
        return _checked(self, f"set velocity {self.part} {_num(self.percent)}")


@dataclass(frozen=True)
class SetVibration:
    intensity: int
    seconds: float

    def to_line(self) -> str:
        return _checked(self, f"set vibration {self.intensity} {_num(self.seconds)}")


@dataclass(frozen=True)
class SetLights:
    red: int
    green: int
    blue: int

    def to_line(self) -> str:
        return _checked(self, f"set lights {self.red} {self.green} {self.blue}")


@dataclass(frozen=True)
class GetState:
    part: str

    def to_line(self) -> str:
        return _checked(self, f"get state {self.part}")


@dataclass(frozen=True)
class GetVelocity:
    part: str

    def to_line(self) -> str:
        return _checked(self, f"get velocity {self.part}")


@dataclass(frozen=True)
class GetEmotion:
    def to_line(self) -> str:
        return "get emotion"


@dataclass(frozen=True)
class Help:
    def to_line(self) -> str:
        return "help"


@dataclass(frozen=True)
class Exit:
    def to_line(self) -> str:
        return "exit"


Command = (
    SetSpeech
    | SetSpeechConfig
    | SetEmotion
    | SetGesture
    | SetAudio
    | SetVideo
    | SetVolume
    | SetState
    | SetVelocity
    | SetVibration
    | SetLights
    | GetState
    | GetVelocity
    | GetEmotion
    | Help
    | Exit
)

HELP_TEXT = """\
commands (words are case-insensitive; one command per line):
  set speech <text>                     say <text>
  set speechconfig <pitch> <speed>      voice pitch 50-200 (QT default 140), speed 20-200 (default 80)
  set emotion <name>                    show a facial expression, e.g. happy (QT/happy)
  set gesture <name> [<speed>]          play a gesture at speed 0.1-4.0 (default 1.0), e.g. marching 1.05
  set audio <file>                      play an audio file (audio_streamer)
  set video <file>                      show a video file (video_streamer)
  set volume <0-100>                    speaker volume in percent
  set state <part> <degrees...>         move a part: head <yaw> <pitch>,
                                        leftarm|rightarm <shoulder pitch> <shoulder roll> <elbow roll>
  set velocity <part> <1-100>           motor velocity of a part in percent
  set vibration <0-100> <seconds>       vibrate (robots that can)
  set lights <r> <g> <b>                light colour 0-255 each (robots that can)
  get state <part>                      joint positions of head|leftarm|rightarm (degrees)
  get velocity <part>                   motor velocity of a part (percent)
  get emotion                           the expression shown last
  help                                  this text
  exit                                  stop the controller"""

_SET_KEYS = (
    "speech",
    "speechconfig",
    "emotion",
    "gesture",
    "audio",
    "video",
    "volume",
    "state",
    "velocity",
    "vibration",
    "lights",
)
_GET_KEYS = ("state", "velocity", "emotion")
_KEY_ALIASES = {"speech_config": "speechconfig", "light": "lights", "position": "state"}


def _int_arg(what: str, text: str, lo: int, hi: int) -> int:
    try:
        value = int(text)
    except ValueError:
        raise ParseError(f"{what} must be a whole number, got {text!r}") from None
    if not lo <= value <= hi:
        raise ParseError(f"{what} {value} is out of range [{lo}, {hi}]")
    return value


def _float_arg(what: str, text: str, lo: float | None = None, hi: float | None = None) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ParseError(f"{what} must be a number, got {text!r}") from None
    if not math.isfinite(value):
        raise ParseError(f"{what} must be a finite number, got {text!r}")
    if lo is not None and hi is not None and not lo <= value <= hi:
        raise ParseError(f"{what} {value:g} is out of range [{lo:g}, {hi:g}]")
    return value


def _arity(usage: str, args: list[str], *counts: int) -> None:
    if len(args) not in counts:
        want = " or ".join(str(c) for c in counts)
        raise ParseError(f"'{usage}' takes {want} argument(s), got {len(args)}")


def _part(text: str) -> str:
    try:
        return canonical_part(text)
    except JointLimitError as exc:
        raise ParseError(str(exc)) from None


def _rest(line: str, words: int) -> str:
    """The text after the first ``words`` whitespace-separated words, spacing kept."""
    rest = line.strip()
    for _ in range(words):
        parts = rest.split(None, 1)
        rest = parts[1] if len(parts) > 1 else ""
    return rest.strip()


def parse_command(line: str) -> Command:
    """Parse one command line; raises :class:`ParseError` when it is not a valid command."""
    if not isinstance(line, str):
        raise ParseError(f"a command is text, got {type(line).__name__}")
    words = line.split()
    if not words:
        raise ParseError("empty command; try 'help'")
    verb = words[0].lower()
    if verb in ("help", "?"):
        _arity(verb, words[1:], 0)
        return Help()
    if verb in ("exit", "quit"):
        _arity(verb, words[1:], 0)
        return Exit()
    if verb not in ("set", "get"):
        raise ParseError(f"unknown command {words[0]!r}; commands start with set, get, help or exit")
    if len(words) < 2:
        keys = _SET_KEYS if verb == "set" else _GET_KEYS
        raise ParseError(f"'{verb}' needs what to {verb}: one of {', '.join(keys)}")
    key = _KEY_ALIASES.get(words[1].lower(), words[1].lower())
    args = words[2:]
    if verb == "get":
        return _parse_get(key, words[1], args)
    return _parse_set(key, words[1], args, line)


def _parse_get(key: str, raw_key: str, args: list[str]) -> Command:
    if key == "state":
        _arity("get state <part>", args, 1)
        return GetState(_part(args[0]))
    if key == "velocity":
        _arity("get velocity <part>", args, 1)
        return GetVelocity(_part(args[0]))
    if key == "emotion":
        _arity("get emotion", args, 0)
        return GetEmotion()
    raise ParseError(f"cannot get {raw_key!r}; one of: {', '.join(_GET_KEYS)}")


def _parse_set(key: str, raw_key: str, args: list[str], line: str) -> Command:
    if key == "speech":
        text = _rest(line, 2)
        if not text:
            raise ParseError("'set speech <text>' needs the text to say")
        return SetSpeech(text)
    if key in ("audio", "video"):
        file = _rest(line, 2)
        if not file:
            raise ParseError(f"'set {key} <file>' needs a file name")
        return SetAudio(file) if key == "audio" else SetVideo(file)
    if key == "speechconfig":
        _arity("set speechconfig <pitch> <speed>", args, 2)
        return SetSpeechConfig(
            _int_arg("speech pitch", args[0], *SPEECH_PITCH_RANGE),
            _int_arg("speech speed", args[1], *SPEECH_SPEED_RANGE),
        )
    if key == "emotion":
        _arity("set emotion <name>", args, 1)
        return SetEmotion(args[0])
    if key == "gesture":
        _arity("set gesture <name> [<speed>]", args, 1, 2)
        speed = _float_arg("gesture speed", args[1], *GESTURE_SPEED_RANGE) if len(args) == 2 else 1.0
        return SetGesture(args[0], speed)
    if key == "volume":
        _arity("set volume <0-100>", args, 1)
        return SetVolume(_int_arg("volume", args[0], *VOLUME_RANGE))
    if key == "state":
        if not args:
            raise ParseError("'set state <part> <degrees...>' needs a part: head, leftarm or rightarm")
        part = _part(args[0])
        joints = PARTS[part]
        if len(args) - 1 != len(joints):
            raise ParseError(
                f"'set state {part}' takes {len(joints)} angle(s) in degrees "
                f"({', '.join(joints)}), got {len(args) - 1}"
            )
        return SetState(part, tuple(_float_arg(j, v) for j, v in zip(joints, args[1:], strict=True)))
    if key == "velocity":
        _arity("set velocity <part> <1-100>", args, 2)
        return SetVelocity(_part(args[0]), _float_arg("velocity", args[1], *VELOCITY_RANGE))
    if key == "vibration":
        _arity("set vibration <0-100> <seconds>", args, 2)
        return SetVibration(
            _int_arg("vibration intensity", args[0], *VIBRATION_RANGE),
            _float_arg("vibration seconds", args[1], *VIBRATION_SECONDS_RANGE),
        )
    if key == "lights":
        _arity("set lights <r> <g> <b>", args, 3)
        r, g, b = (_int_arg(c, v, *LIGHT_RANGE) for c, v in zip(("red", "green", "blue"), args, strict=True))
        return SetLights(r, g, b)
    raise ParseError(f"cannot set {raw_key!r}; one of: {', '.join(_SET_KEYS)}")


def command_name(command: Command) -> str:
    """Short protocol name of a parsed command, e.g. ``'set gesture'``."""
    return _NAMES[type(command)]


_NAMES: dict[type, str] = {
    SetSpeech: "set speech",
    SetSpeechConfig: "set speechconfig",
    SetEmotion: "set emotion",
    SetGesture: "set gesture",
    SetAudio: "set audio",
    SetVideo: "set video",
    SetVolume: "set volume",
    SetState: "set state",
    SetVelocity: "set velocity",
    SetVibration: "set vibration",
    SetLights: "set lights",
    GetState: "get state",
    GetVelocity: "get velocity",
    GetEmotion: "get emotion",
    Help: "help",
    Exit: "exit",
}
