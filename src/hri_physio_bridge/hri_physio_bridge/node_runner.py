"""The one way every console script starts, configures, spins and stops its node.

``main()`` of a node is a few lines::

    def main(argv=None) -> int:
        return run_node(PROG, ReceiverOptions, PhysioReceiverNode, argv=argv, description=__doc__)

:func:`run_node` parses our options (ROS arguments are left to rclpy via
``rclpy.utilities.remove_ros_args``), merges defaults < ``--conf`` YAML < command-line flags,
validates them before ROS starts, calls ``rclpy.init``, builds the node (which declares the
options as ROS parameters with :meth:`ManagedNode.declare_config`, so ``--ros-args -p`` and
``--params-file`` come last), spins it on an executor thread and turns SIGINT/SIGTERM into one
clean shutdown: :meth:`ManagedNode.on_stop`, then :meth:`ManagedNode.run` returns, then
:meth:`ManagedNode.close`. Any configuration problem, wherever it is found, is one line on
stderr and exit status 2, never a traceback. A callback that raises (a bug) stops the node the same
way, after its traceback, and the process ends with status 1 and one line saying so: it never lives
on with an executor that no longer runs.
"""

from __future__ import annotations

import argparse
import contextlib
import faulthandler
import io
import logging
import sys
import threading
import traceback
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TypeVar

import rclpy
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.exceptions import NameValidationException, ParameterException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions

from hri_physio_bridge.config import (
    ConfigError,
    NodeConfig,
    OneLineErrorParser,
    add_config_arguments,
    given_options,
    load_yaml,
)
from hri_physio_bridge.exit_progress import done_line
from hri_physio_bridge.ros_tools import ExecutorThread, shut_down_node_process
from hri_physio_bridge.stop_signals import install_stop_handlers, release_stop_handlers

C = TypeVar("C", bound=NodeConfig)
_INT64 = (-(2**63), 2**63 - 1)


class ManagedNode(Node):
    """A node run by :func:`run_node`. Override what the node needs; the defaults do nothing.

    - :meth:`run` is called on the main thread while an executor spins the node on another;
      its return value is the exit status. By default it waits for a stop signal or for
      :attr:`finished`.
    - :meth:`on_stop` is called on a stop signal (from the signal watcher thread) or after a callback
      failed (from the executor's thread): keep it short and thread-safe (set flags, wake waits).
    - :meth:`close` is called once at the end, before the node is destroyed (flush, stop threads).
    """

    _finished = False
    _run_stop: threading.Event | None = None  # what the default run() waits on

    @property
    def finished(self) -> bool:
        """Set to True (e.g. from a callback) to end :meth:`run` by itself."""
        return self._finished

    @finished.setter
    def finished(self, value: bool) -> None:
        self._finished = value
        if value and self._run_stop is not None:
            self._run_stop.set()  # wakes the default run() at once: it waits, it does not poll

    def declare_config(self, config: C) -> C:
        """Declare every option of ``config`` as a ROS parameter; return the validated result.

        ``config`` holds defaults < ``--conf`` < flags; ``--ros-args`` overrides win. Parameters
        are dynamically typed (a YAML ``130`` for a float option is fine): the model checks
        types and bounds, and descriptors carry the description and range for introspection.
        Unknown parameters given to this node are an error, as unknown options are.

        At run time a parameter is read-only unless its option is ``dynamic``: rclpy refuses a
        change of a read-only one (``parameter is read-only``); a change of a dynamic one is
        checked by the model and applied by :meth:`apply_config`, or refused with the reason.
        """
        cls = type(config)
        values: dict[str, Any] = {}
        for name in cls.model_fields:
            descriptor = _descriptor(cls, name)
            try:
                self.declare_parameter(name, _ros_value(getattr(config, name)), descriptor)
            except ParameterException as exc:
                # The model says what is wrong more clearly than rcl's range message.
                given = getattr(self, "_parameter_overrides", {}).get(name)
                if given is not None:
                    cls.from_mapping({**config.as_dict(), name: given.value}, f"parameter {name}")
                raise ConfigError(f"parameter {name}: {_parameter_problem(exc)}") from None
            values[name] = self.get_parameter(name).value
        overrides = set(getattr(self, "_parameter_overrides", {}))
        unknown = sorted(overrides - set(self._parameters))
        if unknown:
            raise ConfigError(
                f"unknown parameter(s) {', '.join(unknown)} for {self.get_name()}; "
                f"known: {', '.join(cls.model_fields)}"
            )
        resolved = cls.from_mapping(values, source=f"{self.get_name()} parameters")
        self._declared_config: NodeConfig = resolved
        self.add_on_set_parameters_callback(self._on_set_parameters)
        return resolved

    def apply_config(self, config: Any, changed: tuple[str, ...]) -> None:
        """Apply a validated configuration whose dynamic options ``changed`` (raise ValueError to refuse).

        Called on the executor thread. Nodes with ``dynamic`` options override it; the default
        applies nothing, so a node must not mark an option dynamic without overriding this.
        """
        raise ValueError(f"{self.get_name()} applies no change of {', '.join(changed)} at run time")

    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        """Check a run-time change with the configuration model, then let the node apply it."""
        current = getattr(self, "_declared_config", None)
        if current is None:
            return SetParametersResult(successful=True)  # still declaring
        fields = type(current).model_fields
        changes = {p.name: p.value for p in params if p.name in fields}
        if not changes:
            return SetParametersResult(successful=True)  # rclpy's own (use_sim_time, ...)
        fixed = sorted(n for n in changes if not type(current).is_dynamic(n))
        if fixed:  # rclpy refuses read-only parameters before asking; kept for a descriptor changed later
            return SetParametersResult(successful=False,
                                       reason=f"{', '.join(fixed)}: read-only (applied only at start-up)")
        try:
            candidate = type(current).from_mapping({**current.as_dict(), **changes}, "parameter change")
            self.apply_config(candidate, tuple(sorted(changes)))
        except (ConfigError, ValueError) as exc:
            reason = str(exc).removeprefix("parameter change: ")
            self.get_logger().warning(f"refused a parameter change: {reason}")
            return SetParametersResult(successful=False, reason=reason)
        self._declared_config = candidate
        self.get_logger().info("parameter change applied: " + ", ".join(
            f"{n}={getattr(candidate, n)!r}" for n in sorted(changes)))
        return SetParametersResult(successful=True)

    def run(self, stop: threading.Event) -> int:
        self._run_stop = stop
        if not self.finished:
            stop.wait()
        return 0

    def on_stop(self, signal_name: str) -> None:
        self.get_logger().info(f"{signal_name} received: stopping")

    def close(self) -> None:
        """Release what the node holds (called once, on every exit path after construction)."""


def _ros_value(value: Any) -> Any:
    if value is None:
        return ""
    if isinstance(value, tuple):
        value = list(value)
    if isinstance(value, list) and value and not all(isinstance(v, str) for v in value):
        return [float(v) if isinstance(v, int) and not isinstance(v, bool) else v for v in value]
    return value


def _descriptor(cls: type[NodeConfig], name: str) -> ParameterDescriptor:
    bounds = cls.bounds(name)
    desc = ParameterDescriptor(
        name=name, description=cls.describe(name), dynamic_typing=True, read_only=not cls.is_dynamic(name),
        additional_constraints=", ".join(f"{k} {v}" for k, v in bounds.items()),
    )
    low = bounds.get("ge", bounds.get("gt"))
    high = bounds.get("le", bounds.get("lt"))
    kind = cls.kind(name)
    if kind == "float" and (low is not None or high is not None):
        desc.floating_point_range = [FloatingPointRange(
            from_value=float("-inf") if low is None else float(low),
            to_value=float("inf") if high is None else float(high), step=0.0)]
    elif kind == "int" and (low is not None or high is not None):
        desc.integer_range = [IntegerRange(
            from_value=_INT64[0] if low is None else int(low),
            to_value=_INT64[1] if high is None else int(high), step=0)]
    return desc


def _parameter_problem(exc: ParameterException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


# ----------------------------------------------------------------------------------------------
# Logging from logic modules
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
    """A Python logger for the logic modules of node ``name``, writing to its rclpy logger."""
    log = logging.getLogger(f"hri_physio.{name}")
    log.handlers[:] = [RosLogHandler(ros_logger)]
    log.setLevel(logging.DEBUG)
    log.propagate = False
    return log


# ----------------------------------------------------------------------------------------------
# Command line
def build_parser(prog: str, config_cls: type[NodeConfig], description: str | None = None,
                 epilog: str | None = None, extra_arguments: Callable[[argparse.ArgumentParser], None]
                 | None = None, default_conf: Path | None = None) -> argparse.ArgumentParser:
    """The node's parser: ``--conf``, the model's options, and any ``extra_arguments``."""
    seed_keys = ", ".join(config_cls.SEED_KEYS)
    seed = f" The seed's keys ({seed_keys}) are accepted too." if seed_keys else ""
    parser = OneLineErrorParser(
        prog=prog, description=description, formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=(epilog + "\n\n" if epilog else "")
        + "Precedence: defaults < --conf file < command-line options < --ros-args parameters "
        "(-p name:=value, --params-file FILE). Every option is also a ROS parameter of the same name.",
    )
    default = f" (default: the packaged {default_conf.name})" if default_conf else ""
    parser.add_argument("--conf", metavar="FILE",
                        help=f"YAML file with the options below, flat or a ROS params file{default}.{seed}")
    if extra_arguments is not None:
        extra_arguments(parser)
    # An option that extra_arguments wrote its own way (a short flag, several values) keeps its
    # dest, so the model still validates it; it is not added a second time.
    add_config_arguments(parser, config_cls, skip={action.dest for action in parser._actions})
    return parser


def resolve_options(prog: str, config_cls: type[C], args: argparse.Namespace,
                    default_conf: Path | None = None) -> C:
    """Defaults < ``--conf`` file < command-line flags, validated (raises :class:`ConfigError`)."""
    values: dict[str, Any] = {}
    conf = args.conf or default_conf
    source = prog
    if conf:
        values.update(load_yaml(conf, prog))
        source = str(conf)
    flags = given_options(args, config_cls)
    if flags:
        values.update(flags)
        source = f"{source} and command line" if conf else "command line"
    return config_cls.from_mapping(values, source)


def check_ros_arguments(argv: Sequence[str]) -> None:
    """Find the problems rcl would only report with a C-level error: a missing or broken params file."""
    args = list(argv)
    for i, arg in enumerate(args):
        if arg == "--params-file":
            if i + 1 >= len(args):
                raise ConfigError("--params-file needs a file name")
            load_yaml(Path(args[i + 1]))  # exists, UTF-8, a YAML mapping
        elif arg in ("-p", "--param") and (i + 1 >= len(args) or ":=" not in args[i + 1]):
            given = args[i + 1] if i + 1 < len(args) else "nothing"
            raise ConfigError(f"{arg} needs name:=value, got {given!r}")


def _rcl_message(exc: Exception) -> str:
    """rcl's message without the C source locations."""
    return str(exc).split(", at /")[0].strip()


def one_line(exc: Exception) -> str:
    """The first line of an exception's message (its type when it has none), for one-line errors."""
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def fail(prog: str, message: str) -> int:
    print(f"{prog}: error: {message}", file=sys.stderr, flush=True)
    return 2


def _enable_stack_dumps() -> None:
    """A crash, or the launcher's SIGABRT to a node stuck on its way out, prints every thread's stack.

    Left as it is where it is already on (e.g. under pytest), or where stderr is no real file.
    """
    if faulthandler.is_enabled():
        return
    with contextlib.suppress(AttributeError, ValueError, io.UnsupportedOperation):
        faulthandler.enable(file=sys.stderr, all_threads=True)


def run_node(
    prog: str,
    config_cls: type[C],
    make_node: type[ManagedNode] | Callable[[C, argparse.Namespace], ManagedNode],
    *,
    argv: Sequence[str] | None = None,
    description: str | None = None,
    epilog: str | None = None,
    extra_arguments: Callable[[argparse.ArgumentParser], None] | None = None,
    default_conf: Path | None = None,
    startup_errors: tuple[type[Exception], ...] = (),
    offline: Callable[[C, argparse.Namespace], int | None] | None = None,
) -> int:
    """Parse, validate, init, build, spin, stop: the life of one node process. Returns the exit status.

    ``make_node`` is the node class, built as ``make_node(config)``, or a factory
    ``make_node(config, args)`` for a node that also needs the extra flags (``extra_arguments``); the
    node should call :meth:`ManagedNode.declare_config`. Exceptions in ``startup_errors`` raised
    while building are reported like configuration errors (one line, status 2).

    ``offline(config, args)``, if given, runs before ROS starts: a mode that needs no ROS
    (``replayer --info``, ``recorder --repair``) returns its exit status there; None goes on.
    """
    _enable_stack_dumps()
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser(prog, config_cls, description, epilog, extra_arguments, default_conf)
    try:
        check_ros_arguments(argv)
        ours = rclpy.utilities.remove_ros_args([prog, *argv])[1:]
    except ConfigError as exc:
        return fail(prog, str(exc))
    except RuntimeError as exc:  # rclpy's RCLInvalidROSArgsError
        return fail(prog, f"ROS arguments: {_rcl_message(exc)}")
    args = parser.parse_args(ours)
    try:
        config = resolve_options(prog, config_cls, args, default_conf)
    except ConfigError as exc:
        return fail(prog, str(exc))
    if offline is not None:
        try:
            code = offline(config, args)
        except (ConfigError, *startup_errors) as exc:
            return fail(prog, one_line(exc))
        if code is not None:
            return code

    try:
        rclpy.init(args=[prog, *argv], signal_handler_options=SignalHandlerOptions.NO)
    except RuntimeError as exc:  # rclpy's RCLError: arguments rcl could not parse
        return fail(prog, f"ROS arguments: {_rcl_message(exc)}")
    node: ManagedNode | None = None
    spinner: ExecutorThread | None = None
    code: int | None = None
    running: list[ManagedNode] = []
    try:
        try:
            node = make_node(config) if isinstance(make_node, type) else make_node(config, args)
        except (ConfigError, ParameterException, NameValidationException, *startup_errors) as exc:
            return fail(prog, one_line(exc))
        stop = install_stop_handlers(node.on_stop)
        running.append(node)  # held only while it runs: the node must not outlive this function

        def stop_after_a_failed_callback(_exc: BaseException) -> None:
            try:
                for failed in running:
                    failed.on_stop("a failed callback")  # it stops as after a signal, keeping what it has
            except Exception:
                traceback.print_exc(file=sys.stderr)  # said before run() ends; the node stops all the same
            finally:
                stop.set()

        spinner = ExecutorThread(node, on_error=stop_after_a_failed_callback)
        code = node.run(stop)
        if spinner.error is not None:
            error, kind = spinner.error, type(spinner.error).__name__
            what = f"{kind}: {one_line(error)}" if str(error).strip() else kind
            print(f"{prog}: error: a callback failed ({what}); the node stopped", file=sys.stderr, flush=True)
            code = 1
    finally:
        running.clear()
        try:
            if node is not None:
                try:
                    node.close()
                finally:
                    if spinner is not None:
                        spinner.close()
            if code == 0:  # a failed node has said why already, in its error line
                print(done_line(prog, code), file=sys.stderr, flush=True)
        finally:  # also after a close that raised: the bounded teardown always runs
            release_stop_handlers()  # its watcher holds the node (on_stop)
            held, node, spinner = [node], None, None
            shut_down_node_process(held)  # the node destroyed and freed, then ROS shut down, bounded
    return code

