"""qt_controller: text commands on /QtController/input -> the QT robot (real or mock).

Every command line gets one JSON reply on /QtController/output:
``{"t": <ROS time>, "ok": true|false, "command": "<the line>", "message": "...", "data": {...}}``.

Examples::

    qt_controller                          # against mock_qt_robot or a real QT robot
    qt_controller --interactive            # also read commands from stdin
    qt_controller --conf config/qt_controller.yaml --ros-args -p use_sim_time:=true
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import sys
import threading
from typing import Any

import rclpy
from rclpy.duration import Duration
from rclpy.exceptions import NameValidationException, ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import String

from hri_physio_bridge.nodes.common import (
    CliError,
    fail,
    install_stop_handlers,
    load_yaml_conf,
    logic_logger,
    split_ros_args,
)
from qt_controller.commands import HELP_TEXT
from qt_controller.manager import Reply, RobotManager
from qt_controller.nodes.params import declare_options
from qt_controller.qt_robot import QtController, QtControllerOptions

PROG = "qt_controller"
NODE_OPTIONS: dict[str, Any] = {
    "input_topic": "/QtController/input",
    "output_topic": "/QtController/output",
    **{
        k: (list(v) if isinstance(v, list) else v)
        for k, v in dataclasses.asdict(QtControllerOptions()).items()
    },
}
DESCRIPTIONS = {
    "input_topic": "command lines (std_msgs/String)",
    "output_topic": "one JSON reply per command (std_msgs/String)",
    "speech_channel": "talkText (speech with lip animation) or say (voice only)",
    "language": "speech language sent with speech configuration",
    "service_backend": "auto | qt (QT's service types) | json (std_msgs request/reply topics)",
    "service_timeout": "seconds to wait for a robot service (appearing and answering)",
    "discovery_timeout": "seconds to wait for a listener before a topic command fails",
    "require_listeners": "fail topic commands nobody listens to",
    "extra_emotions": "emotion names the robot has beyond QT's standard set",
    "joint_limits": "joint limit overrides, Joint:min:max,...",
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=PROG,
        description="Drive the QT robot (or mock_qt_robot) from text commands on /QtController/input; "
        "replies go to /QtController/output as JSON.",
        epilog="Precedence: defaults < --conf file < command-line options < --ros-args parameters.\n\n"
        + HELP_TEXT,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--conf", help="YAML file with node options (flat, or a ROS params file)")
    parser.add_argument(
        "--interactive", action="store_true", help="also read commands from stdin (end with 'exit' or Ctrl-D)"
    )
    parser.add_argument(
        "--service-backend",
        choices=("auto", "qt", "json"),
        default=None,
        help="how QT's services are reached (default: auto)",
    )
    parser.add_argument(
        "--speech-channel", choices=("talkText", "say"), default=None, help="speech topic (default: talkText)"
    )
    return parser


class QtControllerNode(Node):
    """ROS 2 shell: parameters, the QtController robot, the manager thread, the reply topic."""

    def __init__(self, options: dict[str, Any], **kwargs: Any) -> None:
        super().__init__("qt_controller", **kwargs)
        values = declare_options(self, NODE_OPTIONS, options, DESCRIPTIONS)
        self.log = logic_logger(self.get_name(), self.get_logger())
        self.robot = QtController(self, self.log)
        result = self.robot.configure({k: values[k] for k in QtControllerOptions.KEYS})
        if not result:
            raise ValueError(result.message)
        self.get_logger().info(result.message)
        self.manager = RobotManager(self.robot, self.log)
        self.output = self.create_publisher(String, values["output_topic"], 50)
        self.create_subscription(String, values["input_topic"], self._on_input, 50)
        self.echo = False
        self._stop = threading.Event()
        self._worker: threading.Thread | None = None

    def _on_input(self, msg: String) -> None:
        self.robot.push_command(msg.data)

    def publish_reply(self, reply: Reply) -> None:
        t = self.get_clock().now().nanoseconds * 1e-9
        self.output.publish(String(data=json.dumps(reply.as_dict(t))))
        if self.echo:
            print(("ok: " if reply.ok else "error: ") + reply.message, flush=True)

    def start(self) -> None:
        self._worker = threading.Thread(
            target=self.manager.run, args=(self.publish_reply, self._stop), name="robot-manager", daemon=True
        )
        self._worker.start()

    def stop(self) -> None:
        self._stop.set()
        if self._worker is not None:
            self._worker.join(timeout=5.0)
        self.output.wait_for_all_acked(Duration(seconds=1))  # let the last reply (e.g. to exit) out

    @property
    def exit_requested(self) -> bool:
        return self.manager.exit_requested


def _console(node: QtControllerNode, stop: threading.Event, stream: Any = sys.stdin) -> None:
    print("type commands ('help' lists them, 'exit' quits)", flush=True)
    for line in stream:
        if line.strip():
            node.robot.push_command(line)
    node.robot.push_command("exit")  # stdin closed


def _options_from(args: argparse.Namespace) -> dict[str, Any]:
    options = load_yaml_conf(args.conf, PROG) if args.conf else {}
    unknown = sorted(set(options) - set(NODE_OPTIONS))
    if unknown:
        raise CliError(f"{args.conf}: unknown option(s) {unknown}; known: {sorted(NODE_OPTIONS)}")
    if args.service_backend is not None:
        options["service_backend"] = args.service_backend
    if args.speech_channel is not None:
        options["speech_channel"] = args.speech_channel
    return options


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    ours, ros_args = split_ros_args(argv)
    args = build_parser().parse_args(ours)
    try:
        options = _options_from(args)
    except CliError as exc:
        fail(PROG, str(exc))

    rclpy.init(args=[PROG, *ros_args], signal_handler_options=SignalHandlerOptions.NO)
    node: QtControllerNode | None = None
    executor = SingleThreadedExecutor()
    spin: threading.Thread | None = None
    try:
        try:
            node = QtControllerNode(options)
        except (ValueError, ParameterException, NameValidationException) as exc:
            fail(PROG, str(exc))
        log = node.get_logger()
        stop = install_stop_handlers(lambda name: log.info(f"{name} received: exiting"))
        executor.add_node(node)
        spin = threading.Thread(target=_spin, args=(executor,), name="ros-spin")
        spin.start()
        node.echo = args.interactive
        node.start()
        if args.interactive:
            threading.Thread(target=_console, args=(node, stop), daemon=True).start()
        log.info(f"listening for commands on {node.get_parameter('input_topic').value}")
        while not stop.wait(0.1):
            if node.exit_requested:
                log.info("exit command received: exiting")
                break
        node.stop()
    finally:
        executor.shutdown(timeout_sec=1.0)
        if spin is not None:
            spin.join(timeout=2.0)
        if node is not None:
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0


def _spin(executor: SingleThreadedExecutor) -> None:
    with contextlib.suppress(ExternalShutdownException, KeyboardInterrupt):
        executor.spin()


if __name__ == "__main__":
    sys.exit(main())
