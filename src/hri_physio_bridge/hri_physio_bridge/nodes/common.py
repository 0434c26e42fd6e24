"""Small pieces every node shell of the project shares (no domain logic here)."""

from __future__ import annotations

import logging
import signal
import sys
import threading
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import yaml


class CliError(Exception):
    """A user-facing start-up error: printed as one line, exit code 2."""


def load_yaml_conf(path: str | Path, node_name: str | None = None) -> dict[str, Any]:
    """Load a flat YAML option file (the seed's format) or a ROS params file.

    A ROS params file (``<node>: {ros__parameters: {...}}`` or ``/**: ...``) is
    accepted too, so one file can serve ``--conf`` and ``--params-file``.
    """
    p = Path(path)
    if not p.is_file():
        raise CliError(f"configuration file {p} does not exist")
    try:
        data = yaml.safe_load(p.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        where = ""
        mark = getattr(exc, "problem_mark", None)
        if mark is not None:
            where = f" at line {mark.line + 1}, column {mark.column + 1}"
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise CliError(f"configuration file {p} is not valid YAML{where}: {problem}") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise CliError(f"configuration file {p} must hold key: value pairs, not {type(data).__name__}")
    for key in (node_name, f"/{node_name}" if node_name else None, "/**"):
        section = data.get(key) if key else None
        if isinstance(section, dict) and isinstance(section.get("ros__parameters"), dict):
            return dict(section["ros__parameters"])
    return data


def split_ros_args(argv: Sequence[str]) -> tuple[list[str], list[str]]:
    """Separate our CLI arguments from ``--ros-args ... [--]``."""
    argv = list(argv)
    if "--ros-args" not in argv:
        return argv, []
    i = argv.index("--ros-args")
    rest = argv[i:]
    if "--" in rest:
        j = rest.index("--")
        return argv[:i] + rest[j + 1 :], rest[:j]
    return argv[:i], rest


class RosLogHandler(logging.Handler):
    """Forward Python logging from logic modules to a node's rclpy logger."""

    def __init__(self, ros_logger: Any) -> None:
        super().__init__()
        self._ros = ros_logger

    def emit(self, record: logging.LogRecord) -> None:
        text = self.format(record)
        if record.levelno >= logging.ERROR:
            self._ros.error(text)
        elif record.levelno >= logging.WARNING:
            self._ros.warning(text)
        elif record.levelno >= logging.INFO:
            self._ros.info(text)
        else:
            self._ros.debug(text)


def logic_logger(name: str, ros_logger: Any) -> logging.Logger:
    log = logging.getLogger(f"hri_physio.{name}")
    log.handlers[:] = [RosLogHandler(ros_logger)]
    log.setLevel(logging.DEBUG)
    log.propagate = False
    return log


def install_stop_handlers(on_stop: Callable[[str], None]) -> threading.Event:
    """SIGINT/SIGTERM set the returned event (and call ``on_stop``) instead of raising."""
    stop = threading.Event()

    def handler(signum: int, _frame: Any) -> None:
        name = signal.Signals(signum).name
        if stop.is_set():
            return
        stop.set()
        on_stop(name)

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
    return stop


def fail(prog: str, message: str, code: int = 2) -> None:
    print(f"{prog}: error: {message}", file=sys.stderr)
    raise SystemExit(code)
