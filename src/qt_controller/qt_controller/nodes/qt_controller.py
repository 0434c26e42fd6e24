"""qt_controller: text commands on /QtController/input -> the QT robot (real or mock).

Every command line gets one JSON reply on /QtController/output, in order:
``{"t": <ROS time>, "ok": true|false, "command": "<the line>", "message": "...", "data": {...}}``.
Lines are taken into the controller's own queue as they arrive (reliable, KEEP_ALL), so a
burst loses none; a line beyond ``command_queue_limit`` is answered ``overloaded``.
``exit`` on the topic is refused unless ``allow_remote_exit`` is set.

Examples::

    qt_controller                          # against mock_qt_robot or a real QT robot
    qt_controller --interactive            # also read commands from stdin
    qt_controller --conf config/qt_controller.yaml --ros-args -p use_sim_time:=true
"""

from __future__ import annotations

import json
import sys
import threading
from typing import Any

from rclpy.duration import Duration
from std_msgs.msg import String

from hri_physio_bridge.config import ConfigError
from hri_physio_bridge.node_runner import ManagedNode, logic_logger, run_node
from hri_physio_bridge.qos import command_qos
from qt_controller.commands import HELP_TEXT
from qt_controller.config import QtControllerConfig
from qt_controller.manager import Reply, RobotManager
from qt_controller.qt_controller import QtController

PROG = "qt_controller"


class QtControllerNode(ManagedNode):
    """ROS 2 shell: parameters, the QtController robot, the command queue, the reply topic."""

    def __init__(self, config: QtControllerConfig, **kwargs: Any) -> None:
        super().__init__(PROG, **kwargs)
        self.config = cfg = self.declare_config(config)
        self.log = logic_logger(self.get_name(), self.get_logger())
        self.robot = QtController(self, self.log)
        result = self.robot.configure(cfg.robot_options())
        if not result:
            raise ConfigError(result.message)
        self.get_logger().info(result.message)
        self.manager = RobotManager(self.robot, self.log, allow_remote_exit=cfg.allow_remote_exit,
                                    queue_limit=cfg.command_queue_limit)
        self.echo = cfg.interactive
        self._publish_lock = threading.Lock()  # replies come from the manager and the callbacks
        self.output = self.create_publisher(String, cfg.output_topic, command_qos())
        self.create_subscription(String, cfg.input_topic, self._on_input, command_qos())
        self._worker: threading.Thread | None = None

    def _on_input(self, msg: String) -> None:
        self.submit(msg.data, remote=True)

    def submit(self, line: str, *, remote: bool) -> None:
        """Queue a line; one that cannot be queued is answered at once."""
        immediate = self.manager.submit(line, remote=remote)
        if immediate is not None:
            self.publish_reply(immediate)

    def publish_reply(self, reply: Reply) -> None:
        t = self.get_clock().now().nanoseconds * 1e-9
        with self._publish_lock:
            self.output.publish(String(data=json.dumps(reply.as_dict(t))))
        if self.echo:
            print(("ok: " if reply.ok else "error: ") + reply.message, flush=True)

    def start(self, stop: threading.Event) -> None:
        """Handle queued lines on a worker thread until ``exit`` or ``stop``."""
        def work() -> None:
            try:
                self.manager.run(self.publish_reply, stop)
            finally:
                stop.set()  # an exit command ends the node as a stop does

        self._worker = threading.Thread(target=work, name="robot-manager", daemon=True)
        self._worker.start()

    def join(self, timeout: float = 5.0) -> None:
        if self._worker is not None:
            self._worker.join(timeout)

    def run(self, stop: threading.Event) -> int:
        self.start(stop)
        if self.config.interactive:
            threading.Thread(target=_console, args=(self,), name="console", daemon=True).start()
        self.get_logger().info(f"listening for commands on {self.config.input_topic}")
        stop.wait()  # set by a stop signal (after on_stop) or by the worker's end
        self.manager.request_stop()  # the worker waits for lines: wake it
        self.join()
        if self.manager.exit_requested:
            self.get_logger().info("exit command received: exiting")
        return 0

    def close(self) -> None:
        self.output.wait_for_all_acked(Duration(seconds=1))  # let the last replies (e.g. to exit) out
        self.robot.close()


def _console(node: QtControllerNode, stream: Any = None) -> None:
    stream = sys.stdin if stream is None else stream
    print("type commands ('help' lists them, 'exit' quits)", flush=True)
    for line in stream:
        if line.strip():
            node.submit(line, remote=False)
    node.submit("exit", remote=False)  # stdin closed


def main(argv: list[str] | None = None) -> int:
    return run_node(
        PROG, QtControllerConfig, QtControllerNode, argv=argv, startup_errors=(ValueError,),
        description="Drive the QT robot (or mock_qt_robot) from text commands on /QtController/input; "
        "one JSON reply per line goes to /QtController/output.", epilog=HELP_TEXT,
    )


if __name__ == "__main__":
    sys.exit(main())
