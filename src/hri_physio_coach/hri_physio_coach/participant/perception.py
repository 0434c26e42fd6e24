"""What the simulated participant takes from the robot: the gesture to imitate, its speed,
and the music tempo.

The tempo is what the person hears: the one the audio streamer reports as playing on its status
(``tempo``, or for a file played as it is the tempo its name carries). Before any status has
been heard (no streamer running, e.g. a participant started alone) the tempo comes from the
``set audio`` commands, as the coach names one audio file per tempo.
"""

from __future__ import annotations

import json
import math
import zlib
from collections.abc import Mapping
from typing import Any

from hri_physio_coach.media_names import tempo_from_name as tempo_from_audio
from hri_physio_coach.participant.physiology import MARCHING, SEATED, STEPPING, Activity
from qt_controller.commands import ParseError, SetAudio, SetGesture, parse_command

KNOWN_ACTIVITIES = MARCHING | STEPPING | SEATED
#: Audio streamer states in which the status describes something the person hears.
AUDIBLE_STATES = frozenset({"playing", "fading", "error"})


def heard_tempo(status: Mapping[str, Any]) -> float | None:
    """The tempo (BPM) an audio streamer status says is playing, or None (silence, no tempo known).

    ``tempo`` when the streamer knows it (beats, stretched tracks); for a plain file, the tempo
    in its name (``exercise_125.wav``); nothing for ``relaxing`` or a name without a tempo.
    An ``error`` status still describes what plays (the failed request changed nothing).
    """
    if status.get("state") not in AUDIBLE_STATES:
        return None
    tempo = status.get("tempo")
    if isinstance(tempo, int | float) and not isinstance(tempo, bool) and tempo > 0:
        return float(tempo)
    source = status.get("source")
    return tempo_from_audio(source) if isinstance(source, str) and source else None


class RobotObserver:
    """Turns robot command lines and audio streamer statuses into the participant's :class:`Activity`."""

    def __init__(self, activity: Activity | None = None) -> None:
        self.activity = activity or Activity()
        self.ignored: list[str] = []
        #: True once an audio streamer status was heard: from then on only statuses set the tempo.
        self.hears_streamer = False

    def observe(self, line: str) -> bool:
        """Update from one command line; True when the activity changed."""
        try:
            command = parse_command(line)
        except ParseError:
            self.ignored.append(line)
            return False
        before = self.activity
        if isinstance(command, SetGesture):
            name = command.name if command.name in KNOWN_ACTIVITIES else "rest"
            self.activity = self.activity.with_(name=name, gesture_speed=command.speed)
        elif isinstance(command, SetAudio) and not self.hears_streamer:
            tempo = tempo_from_audio(command.file)
            if tempo is not None:
                self.activity = self.activity.with_(tempo_bpm=tempo)
        return self.activity != before

    def observe_audio_status(self, status: Mapping[str, Any]) -> bool:
        """Update from one ``/audio_streamer/status`` message (decoded JSON); True when the activity changed.

        Without a tempo (silence, a relaxing pad) the cadence keeps the last tempo heard, as it does
        after a ``set audio`` without one.
        """
        self.hears_streamer = True
        tempo = heard_tempo(status)
        if tempo is None or tempo == self.activity.tempo_bpm:
            return False
        self.activity = self.activity.with_(tempo_bpm=tempo)
        return True


def message_key(data: str) -> int:
    """A key of one message the participant follows, the same in every process (its CRC-32)."""
    return zlib.crc32(data.encode("utf-8", "surrogatepass"))


def receipt(topic: str, data: str, heard_at: float) -> str:
    """The participant's confirmation (JSON) that it took in ``data`` from ``topic`` at ``heard_at``.

    The session launcher holds its sim clock until the confirmation of each instruction comes (the
    clock guard): the instruction is then taken up on the same mark on any machine.
    """
    return json.dumps({"topic": topic, "key": message_key(data), "t": heard_at})


def parse_receipt(text: str) -> tuple[str, int, float] | None:
    """(topic, key, heard_at) of a :func:`receipt`, or None when ``text`` is not one."""
    try:
        data = json.loads(text)
        topic, key, heard_at = data["topic"], data["key"], data["t"]
    except (ValueError, TypeError, KeyError):
        return None
    if not (isinstance(topic, str) and isinstance(key, int) and isinstance(heard_at, int | float)):
        return None
    if isinstance(key, bool) or isinstance(heard_at, bool) or not math.isfinite(heard_at):
        return None
    return topic, key, float(heard_at)
