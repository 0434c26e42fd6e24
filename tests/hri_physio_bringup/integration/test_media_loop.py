"""The media in the closed loop over real rclpy: robot commands -> qt_controller -> streamers -> status,
and the simulated participant following the tempo the audio streamer reports as playing."""

from __future__ import annotations

import json
import math
import signal
import threading
import time
from collections.abc import Callable
from typing import Any

import pytest

from helpers import NodeProcess, wait_until
from hri_physio_bridge import topics

pytestmark = [pytest.mark.ros, pytest.mark.lsl]


class Probe:
    """Sends robot command lines (as the coach); collects both streamers' status, the participant's state."""

    def __init__(self, context: Any) -> None:
        from rclpy.node import Node
        from std_msgs.msg import String

        from hri_physio_bridge.qos import command_qos, event_qos
        from hri_physio_bridge.ros_tools import ExecutorThread

        self._string = String
        self.node = Node("media_loop_probe", context=context)
        self.lock = threading.Lock()
        self.got: dict[str, list[dict]] = {"audio": [], "video": [], "participant": []}
        self.commands = self.node.create_publisher(String, topics.QT_COMMANDS, command_qos())
        for key, topic, qos in (("audio", topics.AUDIO_STATUS, event_qos()), ("video", topics.VIDEO_STATUS,
                                event_qos()), ("participant", topics.PARTICIPANT_STATE, event_qos(100))):
            self.node.create_subscription(String, topic, lambda m, key=key: self._add(key, m), qos)
        self._spinner = ExecutorThread(self.node, context=context)

    def _add(self, key: str, msg: Any) -> None:
        with self.lock:
            self.got[key].append(json.loads(msg.data))

    def last(self, key: str) -> dict:
        with self.lock:
            return self.got[key][-1] if self.got[key] else {}

    def find(self, key: str, **fields: Any) -> list[dict]:
        with self.lock:
            return [m for m in self.got[key] if all(m.get(k) == v for k, v in fields.items())]

    def send(self, line: str) -> None:
        self.commands.publish(self._string(data=line))

    def close(self) -> None:
        self._spinner.close()
        self.node.destroy_node()


def playing(status: dict, source: str) -> bool:
    return status.get("state") == "playing" and status.get("source") == source


def resending_until_received(probe: Probe, kind: str, line: str) -> Callable[[], bool]:
    """A wait predicate: true once the streamer received a request; sends ``line`` each second till then."""
    sent_at = [-math.inf]

    def received() -> bool:
        status = probe.last(kind)
        if status and status["requests"]["received"] >= 1:
            return True
        if time.monotonic() - sent_at[0] >= 1.0:
            probe.send(line)
            sent_at[0] = time.monotonic()
        return False
    return received


def test_set_audio_and_video_reach_the_streamers_and_the_participant_hears_what_plays(
        ros_context: Any, lsl_name: str) -> None:
    probe = Probe(ros_context)
    controller = NodeProcess("qt_controller")
    audio = NodeProcess("audio_streamer", "--cache-dir", "", "--ros-args", "-p", "sink:=null",
                        "-p", "fade:=0.2", "-p", "status_rate:=4.0")
    video = NodeProcess("video_streamer", "--ros-args", "-p", "display:=offscreen", "-p", "status_rate:=4.0",
                        "-p", "fps:=10.0")
    person = NodeProcess("simulated_participant", "--name-prefix", lsl_name)
    try:
        with controller, audio, video, person:
            wait_until(lambda: probe.commands.get_subscription_count() >= 2
                       and probe.node.count_subscribers(topics.AUDIO_REQUEST) >= 1
                       and probe.node.count_subscribers(topics.VIDEO_REQUEST) >= 1
                       and probe.node.count_publishers(topics.AUDIO_REQUEST) >= 1
                       and probe.last("audio") and probe.last("video") and probe.last("participant"), 60,
                       lambda: "\n".join(p.output for p in (controller, audio, video, person)))
            # Warm-up: a request that reached each streamer shows that every writer on the way has
            # matched its reader (the graph counts above can come first; a line sent before is lost).
            for kind, line in (("audio", "set audio relaxing"), ("video", "set video splash")):
                wait_until(resending_until_received(probe, kind, line), 60,
                           lambda kind=kind: f"a warm-up request at the {kind} streamer: {probe.last(kind)}")
            probe.send("set audio beat:125")
            probe.send("set video marching")
            wait_until(lambda: playing(probe.last("audio"), "beat:125"), 60,
                       lambda: f"beat:125 playing; last {probe.last('audio')}\n{audio.output}")
            assert probe.last("audio")["tempo"] == 125.0 and probe.last("audio")["sink"] == "null"
            wait_until(lambda: playing(probe.last("video"), "marching"), 60,
                       lambda: f"marching on screen; last {probe.last('video')}\n{video.output}")
            assert probe.last("video")["display"] == "offscreen" and probe.last("video")["kind"] == "activity"
            # The video's placeholder moves at the tempo the audio streamer plays.
            wait_until(lambda: probe.last("video").get("tempo") == 125.0, 30,
                       lambda: str(probe.last("video")))
            wait_until(lambda: probe.last("participant").get("tempo_bpm") == 125.0, 30,
                       lambda: f"the participant at 125 BPM; last {probe.last('participant')}")
            # A request the streamer refuses (out of range) changes what is asked for, not what is heard:
            # a participant following the commands would move to 300 BPM.
            probe.send("set audio beat:300")
            wait_until(lambda: probe.find("audio", state="error", request="beat:300"), 30,
                       lambda: str(probe.last("audio")))
            assert probe.find("audio", state="error", request="beat:300")[0]["source"] == "beat:125"
            probe.send("set audio beat:110")
            wait_until(lambda: playing(probe.last("audio"), "beat:110"), 60, lambda: str(probe.last("audio")))
            wait_until(lambda: probe.last("participant").get("tempo_bpm") == 110.0, 30,
                       lambda: f"the participant at 110 BPM; last {probe.last('participant')}")
            with probe.lock:
                heard = {s["tempo_bpm"] for s in probe.got["participant"]}
            assert 300.0 not in heard, heard
            for proc in (person, video, audio, controller):
                assert proc.stop(signal.SIGTERM, timeout=30) == 0, proc.output
        assert person.output.count("follows what /audio_streamer/status reports") == 1  # said once
    finally:
        probe.close()


def test_a_participant_alone_follows_the_commands_and_says_so(ros_context: Any, lsl_name: str) -> None:
    probe = Probe(ros_context)
    try:
        with NodeProcess("simulated_participant", "--name-prefix", lsl_name) as person:
            wait_until(lambda: probe.commands.get_subscription_count() >= 1 and probe.last("participant"), 60,
                       lambda: person.output)
            probe.send("set audio ./audio/exercise_130.wav")
            probe.send("set audio beat:135")
            wait_until(lambda: probe.last("participant").get("tempo_bpm") == 135.0, 30,
                       lambda: f"135 BPM from the commands; last {probe.last('participant')}")
            assert person.stop(signal.SIGTERM) == 0, person.output
        assert person.output.count("no audio streamer status") == 1  # one info line, not one per command
    finally:
        probe.close()
