"""Every topic name of the system, defined once (plain strings: importable without ROS).

Raw streams from the bridge are ``/physio/<source>/<metric>``, processing outputs
``/physio/<source>/<metric>/<feature>``, the scenario's state and events ``/coach/...``, robot
commands ``/QtController/input`` (docs/ARCHITECTURE.md has the whole graph). Node defaults,
launchers and tests import these names; no topic string is repeated across packages.
"""

from __future__ import annotations

# --- physiology (bridge and processing) ---------------------------------------------------------
POLAR_H10_ECG = "/physio/polar_h10/ecg"
POLAR_H10_HR = "/physio/polar_h10/hr"
POLAR_H10_ECG_HR = "/physio/polar_h10/ecg/hr"

# --- robot command protocol (qt_controller) -------------------------------------------------------
QT_COMMANDS = "/QtController/input"
QT_REPLIES = "/QtController/output"

# --- the QT robot's own interface (mirrored by mock_qt_robot) -------------------------------------
QT_TALK_TEXT = "/qt_robot/behavior/talkText"
QT_SPEECH_SAY = "/qt_robot/speech/say"
QT_EMOTION = "/qt_robot/emotion/show"
QT_JOINT_STATE = "/qt_robot/joints/state"
QT_GESTURE_PLAY = "/qt_robot/gesture/play"
QT_SPEECH_CONFIG = "/qt_robot/speech/config"
QT_SET_VOLUME = "/qt_robot/setting/setVolume"
QT_SET_VELOCITY = "/qt_robot/motors/setVelocity"
QT_MOCK_EVENTS = "/qt_robot/mock/events"


def qt_joint_command(stem: str) -> str:
    """The position command topic of one part (``head``, ``right_arm``, ``left_arm``)."""
    return f"/qt_robot/{stem}_position/command"


# --- media ---------------------------------------------------------------------------------------
AUDIO_REQUEST = "/audio_streamer/audio_name"
AUDIO_STATUS = "/audio_streamer/status"
VIDEO_REQUEST = "/video_streamer/video_name"
VIDEO_STATUS = "/video_streamer/status"
VIDEO_PREVIEW = "/video_streamer/preview"
#: The last request sent to each streamer, latched (transient-local, depth 1): a streamer that starts
#: late or is restarted plays what it should, without any request being sent twice.
AUDIO_CURRENT = "/audio_streamer/current_request"
VIDEO_CURRENT = "/video_streamer/current_request"

# --- the coach and the simulated participant ------------------------------------------------------
COACH_EVENTS = "/coach/events"
COACH_STATE = "/coach/state"
COACH_CONTROL = "/coach/control"
PARTICIPANT_STATE = "/participant/state"
#: The simulated participant's confirmation of each robot command and audio status it took in (JSON):
#: the session launcher holds sim time until it comes, so the person takes every instruction up on
#: the same mark however busy the machine.
PARTICIPANT_HEARD = "/participant/heard"

# --- the session launcher ---------------------------------------------------------------------------
#: Supervision events (JSON): a node restarted, a receiver's gap, a node whose loss ended the session.
SESSION_EVENTS = "/session/events"
#: A lab of several hosts: each host launcher's heartbeat (JSON), and the station's session end (latched).
LAB_HOSTS = "/lab/hosts"
LAB_SESSION = "/lab/session"
