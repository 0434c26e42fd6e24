"""What the simulated participant takes from the robot: the gesture to imitate, its speed,
and the music tempo (the coach plays one audio file per tempo, named with its BPM).
"""

from __future__ import annotations

from hri_physio_coach.media_names import tempo_from_name as tempo_from_audio
from hri_physio_coach.participant.physiology import MARCHING, SEATED, STEPPING, Activity
from qt_controller.commands import ParseError, SetAudio, SetGesture, parse_command

KNOWN_ACTIVITIES = MARCHING | STEPPING | SEATED


class RobotObserver:
    """Turns robot command lines into the participant's current :class:`Activity`."""

    def __init__(self, activity: Activity | None = None) -> None:
        self.activity = activity or Activity()
        self.ignored: list[str] = []

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
        elif isinstance(command, SetAudio):
            tempo = tempo_from_audio(command.file)
            if tempo is not None:
                self.activity = self.activity.with_(tempo_bpm=tempo)
        return self.activity != before
