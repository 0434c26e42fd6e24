"""simulated_participant: a person on the exercise step, wearing a (simulated) Polar H10.

Listens to the robot commands on /QtController/input (gesture, gesture speed) and to the music
the audio streamer reports as playing on /audio_streamer/status (its tempo: what the person hears;
until a status arrives, e.g. with no streamer running, the tempo named in ``set audio``),
runs the heart-rate model of docs/PARTICIPANT_MODEL.md on ROS time (so it follows /clock under
use_sim_time), and streams what a Polar H10 would: ECG (130 Hz), HR (1 Hz) and RR intervals
on LSL, named ``[<name_prefix>/]PolarH10/<device_id>/<ECG|HR|RR>``. Its true model state goes
to /participant/state (JSON) for evaluation; each command and audio status it took in is confirmed
on /participant/heard (JSON: topic, key, when), which the session launcher's clock guard waits for.

Until the coach's ``session_start`` on /coach/events the person rests on a separate random
stream; from then the model runs from its seed as ``hri_physio_evaluate`` runs it
(:class:`~hri_physio_coach.participant.stream.StrapStream`; the streams stay continuous).

Examples::

    simulated_participant
    simulated_participant --age 45 --seed 3 --device-id SIM0002
    simulated_participant --ros-args -p use_sim_time:=true -p age:=45.0
"""

from __future__ import annotations

import json
import sys
import threading
from typing import Any

import numpy as np
import pylsl
from std_msgs.msg import String

from hri_physio_bridge.frames import Frame
from hri_physio_bridge.node_runner import ManagedNode, run_node
from hri_physio_bridge.qos import command_qos, event_qos
from hri_physio_bridge.streamers.base import StreamerError, StreamSpec
from hri_physio_bridge.streamers.lsl import LslStreamer
from hri_physio_coach.participant.perception import RobotObserver, receipt
from hri_physio_coach.participant.physiology import takes_effect
from hri_physio_coach.participant.stream import StrapStream, strap_start
from hri_physio_coach.participant_config import PARTICIPANT_NODE, ParticipantNodeConfig

PROG = PARTICIPANT_NODE


class SimulatedParticipantNode(ManagedNode):
    """The model on a ROS timer, its strap on LSL outlets, the robot's commands as its input."""

    def __init__(self, config: ParticipantNodeConfig, **kwargs: Any) -> None:
        super().__init__(PROG, **kwargs)
        self.config = cfg = self.declare_config(config)
        self.params = cfg.params
        # The streams start at the first tick with a valid ROS time: under use_sim_time that is
        # 0 until the first /clock message, and starting then would make the first step jump
        # from 0 to the clock's epoch.
        self.strap: StrapStream | None = None
        self._session_start: float | None = None  # the coach's session_start (the first one heard)
        self.lsl_offset = 0.0
        self.observer = RobotObserver()
        self._lock = threading.Lock()  # ticks (executor thread) and close (main thread)
        self.outlets: dict[str, LslStreamer] = {}
        try:
            for kind, rate in (("ECG", cfg.ecg_rate), ("HR", 1.0), ("RR", 0.0)):
                outlet = LslStreamer(cfg.lsl_name(kind))
                outlet.open_output(StreamSpec(name=outlet.name, type=kind, nominal_rate=rate,
                                              source_id=f"{cfg.device_id}-{kind}", channels=(kind,)))
                self.outlets[kind] = outlet
        except Exception:
            self.close()
            raise
        self.state_pub = self.create_publisher(String, cfg.state_topic, event_qos(100))
        self.heard_pub = self.create_publisher(String, cfg.heard_topic, event_qos(100))
        self.create_subscription(String, cfg.command_topic, self._on_command, command_qos())
        self.create_subscription(String, cfg.audio_status_topic, self._on_audio_status, event_qos())
        self.create_subscription(String, cfg.session_events_topic, self._on_coach_event, event_qos())
        self._said_tempo_from_commands = False
        self.create_timer(cfg.update_period, self._tick)
        self._last_state = 0.0
        p = self.params
        self.get_logger().info(
            f"participant (age {p.age:g}, HR rest {p.hr_rest:g}, HRmax {p.hr_max_true:g}) streaming as "
            f"{cfg.lsl_name('*')} on LSL"
        )

    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _start_model(self, now: float) -> StrapStream:
        cfg = self.config
        self.strap = StrapStream(self.params, cfg.seed, strap_start(now), ecg_rate=cfg.ecg_rate)
        self.strap.set_activity(self.observer.activity)
        if self._session_start is not None:
            self.strap.start_session(self._session_start)
        # LSL timestamps: model (ROS) time shifted onto the LSL clock at start-up, so in real
        # time they are ordinary LSL timestamps and under /clock they advance with sim time.
        self.lsl_offset = pylsl.local_clock() - now
        self._last_state = now
        self.get_logger().info(f"model started at ROS time {now:.3f} s (at rest until the session starts)")
        return self.strap

    def _on_coach_event(self, msg: String) -> None:
        try:
            event = json.loads(msg.data)
        except ValueError:
            return
        if not isinstance(event, dict) or event.get("event") != "session_start":
            return
        t = event.get("t")
        if not isinstance(t, int | float) or isinstance(t, bool):
            self.get_logger().warning(f"a session_start without a time on {self.config.session_events_topic}")
            return
        with self._lock:
            if self._session_start is None:
                self._session_start = float(t)  # instructions are taken up on marks counted from it
            if self.strap is None:
                return
            if self.strap.start_session(float(t)):
                self.get_logger().info(f"session started at ROS time {float(t):.3f} s: the seeded model "
                                       "takes over at the next fitting second")
            else:
                self.get_logger().info("another session_start: the model keeps running (one per participant)")

    def _confirm(self, topic: str, msg: String) -> None:
        """Say that ``msg`` was taken in, and when (the launcher's clock guard waits for it)."""
        self.heard_pub.publish(String(data=receipt(topic, msg.data, self._now())))

    def _on_command(self, msg: String) -> None:
        with self._lock:
            changed = self.observer.observe(msg.data)
            if (not self.observer.hears_streamer and not self._said_tempo_from_commands
                    and msg.data.startswith("set audio")):
                self._said_tempo_from_commands = True
                self.get_logger().info(f"no audio streamer status on {self.config.audio_status_topic} yet: "
                                       "the music tempo follows the 'set audio' commands")
            if changed:
                self._apply_activity()
        self._confirm(self.config.command_topic, msg)

    def _on_audio_status(self, msg: String) -> None:
        try:
            self._follow_audio_status(msg)
        finally:
            self._confirm(self.config.audio_status_topic, msg)

    def _follow_audio_status(self, msg: String) -> None:
        try:
            status = json.loads(msg.data)
        except ValueError:
            return  # not a status this node can read; the recorder keeps it as it is
        if not isinstance(status, dict):
            return
        with self._lock:
            first = not self.observer.hears_streamer
            changed = self.observer.observe_audio_status(status)
            if first:
                self.get_logger().info(f"the music tempo follows what {self.config.audio_status_topic} "
                                       "reports as playing")
            if changed:
                self._apply_activity()

    def _apply_activity(self) -> None:
        at = takes_effect(self._now(), self._session_start, self.params.reaction_period)
        if self.strap is not None:
            self.strap.set_activity(self.observer.activity, at)
        when = "now" if at is None else f"from ROS time {at:.3f} s"
        self.get_logger().info(f"{when} doing {self.observer.activity}")

    def _push(self, kind: str, t: np.ndarray, values: np.ndarray) -> None:
        if len(t):
            self.outlets[kind].publish(Frame(t + self.lsl_offset, values.reshape(-1, 1)))

    def _tick(self) -> None:
        with self._lock:
            if not self.outlets:
                return  # closing
            now = self._now()
            if now <= 0.0:
                return  # use_sim_time and no /clock yet
            strap = self.strap if self.strap is not None else self._start_model(now)
            if now <= strap.t:
                return  # sim time paused or went backwards (a replay restarted): wait
            was_in_session = strap.in_session
            out = strap.advance(now)
            if strap.in_session and not was_in_session:
                self.get_logger().info(f"seeded session model running from ROS time {strap.session_t0:.3f} s"
                                       + ("" if strap.bridged else " (no bridging beat found: one odd beat)"))
            self._push("ECG", out.ecg_t, out.ecg_mv)
            self._push("HR", out.hr_t, out.hr_bpm)
            self._push("RR", out.rr_t, out.rr_s * 1000.0)
            if now - self._last_state >= 1.0:
                self._last_state = now
                model = strap.sim
                a = model.activity
                self.state_pub.publish(String(data=json.dumps({
                    "t": now, "hr_model": model.hr, "fraction_hrr": model.kinetics.fraction_hrr,
                    "activity": a.name, "tempo_bpm": a.tempo_bpm, "gesture_speed": a.gesture_speed,
                    "session_model_t0": strap.session_t0,
                })))

    def close(self) -> None:
        with self._lock:
            outlets, self.outlets = self.outlets, {}
        for outlet in outlets.values():
            outlet.close()


def main(argv: list[str] | None = None) -> int:
    return run_node(PROG, ParticipantNodeConfig, SimulatedParticipantNode, argv=argv, description=__doc__,
                    startup_errors=(StreamerError,))


if __name__ == "__main__":
    sys.exit(main())
