"""simulated_participant: a person on the exercise step, wearing a (simulated) Polar H10.

Listens to the robot commands on /QtController/input (gesture, gesture speed,
music tempo), runs the heart-rate model of PARTICIPANT_MODEL.md on ROS time
(so it follows /clock under use_sim_time), and streams what a Polar H10 would:
ECG (130 Hz), HR (1 Hz) and RR intervals on LSL, named
``PolarH10/<device_id>/<ECG|HR|RR>``. Its true model state goes to
``/participant/state`` (JSON) for evaluation.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from typing import Any

import numpy as np
import pylsl
import rclpy
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import String

from hri_physio_bridge.frames import Frame
from hri_physio_bridge.nodes.common import install_stop_handlers, split_ros_args
from hri_physio_bridge.streamers.base import StreamSpec
from hri_physio_bridge.streamers.lsl import LslStreamer
from hri_physio_coach.participant.cardiac import ParticipantSimulator
from hri_physio_coach.participant.perception import RobotObserver
from hri_physio_coach.participant.physiology import ParticipantParams

PROG = "simulated_participant"
_PARAM_FIELDS = [f for f in dataclasses.fields(ParticipantParams) if f.type in ("float", "bool")]


class SimulatedParticipantNode(Node):
    def __init__(self, **kwargs: Any) -> None:
        super().__init__(PROG, **kwargs)
        defaults = ParticipantParams()
        for f in _PARAM_FIELDS:
            self.declare_parameter(f.name, getattr(defaults, f.name))
        self.declare_parameter("seed", 0)
        self.declare_parameter("device_id", "SIM0001")
        self.declare_parameter("name_prefix", "")
        self.declare_parameter("ecg_rate", 130.0)
        self.declare_parameter("update_period", 0.1)
        self.declare_parameter("command_topic", "/QtController/input")
        values = {f.name: self.get_parameter(f.name).value for f in _PARAM_FIELDS}
        self.params = ParticipantParams(**values)
        self.params.validate()
        period = float(self.get_parameter("update_period").value)
        if period <= 0:
            raise ValueError(f"update_period must be > 0 s, got {period}")
        device = self.get_parameter("device_id").value
        prefix = self.get_parameter("name_prefix").value
        prefix = f"{prefix.rstrip('/')}/" if prefix else ""
        rate = float(self.get_parameter("ecg_rate").value)

        self.seed = int(self.get_parameter("seed").value)
        self.ecg_rate = rate
        # The model starts at the first tick with a valid ROS time: under use_sim_time that is
        # 0 until the first /clock message, and starting then would make the first step jump
        # from 0 to the clock's epoch.
        self.sim: ParticipantSimulator | None = None
        self.lsl_offset = 0.0
        self.observer = RobotObserver()
        self.outlets: dict[str, LslStreamer] = {}
        for kind, stream_rate, label in (("ECG", rate, "ECG"), ("HR", 1.0, "HR"), ("RR", 0.0, "RR")):
            s = LslStreamer(f"{prefix}PolarH10/{device}/{kind}")
            s.open_output(StreamSpec(name=s.name, type=kind, nominal_rate=stream_rate,
                                     source_id=f"{device}-{kind}", channels=(label,)))
            self.outlets[kind] = s
        self.state_pub = self.create_publisher(String, "/participant/state", 10)
        self.create_subscription(String, self.get_parameter("command_topic").value, self._on_command, 100)
        self.create_timer(period, self._tick)
        self._last_state = 0.0
        self.get_logger().info(
            f"participant (age {self.params.age:g}, HR rest {self.params.hr_rest:g}, HRmax "
            f"{self.params.hr_max_true:g}) streaming as PolarH10/{device} on LSL"
        )

    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _start_model(self, now: float) -> ParticipantSimulator:
        self.sim = ParticipantSimulator(self.params, seed=self.seed, ecg_rate=self.ecg_rate, t0=now)
        self.sim.set_activity(self.observer.activity)
        # LSL timestamps: model (ROS) time shifted onto the LSL clock at start-up, so in real
        # time they are ordinary LSL timestamps and under /clock they advance with sim time.
        self.lsl_offset = pylsl.local_clock() - now
        self._last_state = now
        self.get_logger().info(f"model started at ROS time {now:.3f} s")
        return self.sim

    def _on_command(self, msg: String) -> None:
        if self.observer.observe(msg.data):
            if self.sim is not None:
                self.sim.set_activity(self.observer.activity)
            self.get_logger().info(f"now doing {self.observer.activity}")

    def _push(self, kind: str, t: np.ndarray, values: np.ndarray) -> None:
        if len(t):
            self.outlets[kind].publish(Frame(t + self.lsl_offset, values.reshape(-1, 1)))

    def _tick(self) -> None:
        now = self._now()
        if now <= 0.0:
            return  # use_sim_time and no /clock yet
        sim = self.sim if self.sim is not None else self._start_model(now)
        if now <= sim.t:
            return  # sim time paused or went backwards (a replay restarted): wait
        out = sim.advance(now)
        self._push("ECG", out.ecg_t, out.ecg_mv)
        self._push("HR", out.hr_t, out.hr_bpm)
        self._push("RR", out.rr_t, out.rr_s * 1000.0)
        if now - self._last_state >= 1.0:
            self._last_state = now
            a = sim.activity
            self.state_pub.publish(String(data=json.dumps({
                "t": now, "hr_model": sim.hr, "fraction_hrr": sim.kinetics.fraction_hrr,
                "activity": a.name, "tempo_bpm": a.tempo_bpm, "gesture_speed": a.gesture_speed,
            })))

    def close(self) -> None:
        for s in self.outlets.values():
            s.close()


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    ours, ros_args = split_ros_args(argv)
    parser = argparse.ArgumentParser(
        prog=PROG, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="Participant parameters are ROS parameters: " + ", ".join(f.name for f in _PARAM_FIELDS)
        + ", seed, device_id, name_prefix, ecg_rate, update_period, command_topic "
        "(e.g. --ros-args -p age:=45.0 -p use_sim_time:=true).",
    )
    parser.parse_args(ours)
    rclpy.init(args=[PROG, *ros_args], signal_handler_options=SignalHandlerOptions.NO)
    node: SimulatedParticipantNode | None = None
    try:
        try:
            node = SimulatedParticipantNode()
        except (ValueError, TypeError) as exc:
            print(f"{PROG}: error: {exc}", file=sys.stderr)
            return 2
        stop = install_stop_handlers(lambda name: None)
        while not stop.is_set() and rclpy.ok():
            rclpy.spin_once(node, timeout_sec=0.1)
        node.get_logger().info("stopping")
        return 0
    finally:
        if node is not None:
            node.close()
            node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main())
