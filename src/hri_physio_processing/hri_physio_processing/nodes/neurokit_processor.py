"""neurokit_processor: ECG (or PPG, EDA) features per sliding window, from any stream to ROS 2 (+ LSL).

Reads frames from a ROS 2 topic, an LSL stream or a CSV log, windows them (default 60 s
every 5 s), runs NeuroKit2 on each window and publishes, under ``<output_prefix>``:

  ECG  clean, rpeaks, beat_hr (frames); hr, sdnn, rmssd, pnn50, lf, hf, lfhf, quality
  PPG  clean, peaks, beat_hr (frames);  the same scalars
  EDA  clean, scr_peaks (frames);        tonic, scr_count, scr_amplitude
  status (std_msgs/String JSON with "t"): window extent, flags, why a feature is NaN

Scalars are one-sample frames [t, value] stamped with the end of their window.

Examples::

    neurokit_processor --input ros:/physio/polar_h10/ecg
    neurokit_processor --input lsl:PolarH10/SIM0001/ECG --output-prefix /physio/polar_h10/ecg
    neurokit_processor --conf processor.yaml
    neurokit_processor --ros-args --params-file params.yaml
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import sys
import threading
import time
from typing import Any

from hri_physio_processing.config import ConfigError, ProcessorConfig, translate_seed_keys

PROG = "neurokit_processor"
_HELP = {
    "input": "source: ros:/<topic>, lsl:<name>[?type=&source_id=], csv:<file>[?rate=] "
    "(no scheme = LSL name, as the seed)",
    "output_prefix": "topic prefix of the outputs, e.g. /physio/polar_h10/ecg (default: the input topic)",
    "mode": "signal: ecg | ppg | eda",
    "sampling_rate": "nominal rate of the input in Hz (checked against the timestamps)",
    "num_channels": "channels per input sample (ROS 2 input frames must match)",
    "channel": "which input channel to process (0-based)",
    "window_seconds": "seconds of signal per processed window",
    "hop_seconds": "seconds between window starts (window - hop = overlap)",
    "lsl_output": "also publish every output on LSL",
    "lsl_prefix": "LSL stream-name prefix (default: output_prefix)",
    "quality_method": "NeuroKit2 ECG quality: templatematch | averageQRS | zhao2018 | none",
    "min_quality": "windows with a lower quality are flagged (features NaN)",
    "min_beats": "fewer beats in a window: features NaN",
    "min_hr": "mean rate below this (bpm): flagged, not a heart signal",
    "max_hr": "mean rate above this (bpm): flagged",
    "flatline_seconds": "a constant stretch this long flags the window (0 = mode default)",
    "saturation_fraction": "this share of samples at the extremes flags the window (0 = mode default)",
    "rate_tolerance": "relative mismatch between timestamps and sampling_rate that flags a window",
    "gap_factor": "timestamp step (in sample periods) that counts as a gap and restarts windows",
    "min_window_seconds": "shortest stretch between gaps (or at the end) still processed",
    "edge_guard_seconds": "overlapping windows publish peaks up to this far from their end",
    "dedup_seconds": "peaks closer than this to the last published one are duplicates (0 = mode default)",
    "correct_artifacts": "let NeuroKit2 correct R-peak artefacts (ecg_peaks correct_artifacts)",
    "resolve_timeout": "seconds to wait for the input stream per attempt",
    "wait_for_consumers": "seconds to wait for a listener on every ROS output before reading input "
    "(topics are volatile: a log replay would otherwise lose its first windows; 0 = no wait)",
    "verbose": "log every window",
}


def _to_bool(text: str) -> bool:
    low = text.strip().lower()
    if low in ("1", "true", "yes", "on"):
        return True
    if low in ("0", "false", "no", "off"):
        return False
    raise argparse.ArgumentTypeError(f"expected true/false, got {text!r}")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=PROG, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="Precedence: defaults < --conf file < command-line options < --ros-args parameters. "
        "The seed's YAML keys (name, input, buffer, window, verbose) are accepted in --conf files.",
    )
    parser.add_argument("--conf", metavar="FILE", help="YAML file with the options below (flat keys)")
    defaults = ProcessorConfig()
    for f in dataclasses.fields(ProcessorConfig):
        default = getattr(defaults, f.name)
        kind = {bool: _to_bool, int: int, float: float}.get(type(default), str)
        parser.add_argument(
            "--" + f.name.replace("_", "-"), dest=f.name, type=kind, default=None,
            help=f"{_HELP[f.name]} (default: {default!r})",
        )
    return parser


def gather_options(args: argparse.Namespace) -> dict[str, Any]:
    """--conf file, then command-line flags on top (both checked here, before ROS starts)."""
    from hri_physio_bridge.nodes.common import CliError, load_yaml_conf

    options: dict[str, Any] = {}
    if args.conf:
        conf = {str(k).replace("-", "_"): v for k, v in load_yaml_conf(args.conf, PROG).items()}
        try:
            conf = translate_seed_keys(conf, args.conf)
        except ConfigError as exc:
            raise CliError(str(exc)) from None
        unknown = sorted(set(conf) - set(ProcessorConfig.KEYS))
        if unknown:
            raise CliError(f"{args.conf}: unknown option(s) {unknown}; known: {list(ProcessorConfig.KEYS)}")
        options.update(conf)
    options.update({k: v for k, v in vars(args).items() if k in ProcessorConfig.KEYS and v is not None})
    return options


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    from hri_physio_bridge.nodes.common import CliError, fail, install_stop_handlers, split_ros_args

    ours, ros_args = split_ros_args(argv)
    args = build_parser().parse_args(ours)
    try:
        options = gather_options(args)
        ProcessorConfig.from_mapping(options, source=PROG)  # fail fast, before ROS starts
    except (CliError, ConfigError) as exc:
        fail(PROG, str(exc))

    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    from hri_physio_bridge.streamers import StreamerError
    from hri_physio_processing.nodes.runner import NeurokitProcessorNode, ProcessorRunner

    rclpy.init(args=[PROG, *ros_args], signal_handler_options=SignalHandlerOptions.NO)
    node = None
    executor = SingleThreadedExecutor()
    spin: threading.Thread | None = None
    code = 0

    def spin_forever() -> None:
        with contextlib.suppress(ExternalShutdownException, KeyboardInterrupt):
            executor.spin()

    try:
        try:
            node = NeurokitProcessorNode(options)
            runner = ProcessorRunner(node)
        except (ConfigError, ValueError, StreamerError) as exc:
            fail(PROG, str(exc))
        log = node.get_logger()
        stop = install_stop_handlers(lambda name: log.info(f"{name} received: finishing the last window"))
        executor.add_node(node)
        spin = threading.Thread(target=spin_forever, name="ros-spin", daemon=True)
        spin.start()
        code = runner.run(stop)
        # Reliable delivery of the last outputs before the publishers go away.
        time.sleep(0.2)
        log.info(f"done: {json.dumps(runner.processor.stats.as_dict())}")
    finally:
        if node is not None:
            with contextlib.suppress(Exception):
                node.close_outputs()
        executor.shutdown(timeout_sec=1.0)
        if spin is not None:
            spin.join(timeout=2.0)
        if node is not None:
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return code


if __name__ == "__main__":
    sys.exit(main())
