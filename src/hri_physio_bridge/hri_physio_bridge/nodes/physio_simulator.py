"""physio_simulator: NeuroKit2 signals streamed onto LSL in real time, named like a Polar strap.

Streams (one float64 channel each; with --name-prefix P every name starts with P/):
  ecg   PolarH10/<device-id>/ECG      --rate Hz, millivolts
  hr    PolarH10/<device-id>/HR       1 Hz, whole bpm measured on the simulated ECG
  ppg   PolarOH1/<device-id>/PPG      --rate Hz
  eda   NeuroKitSim/<device-id>/EDA   --rate Hz, microsiemens
  emg   NeuroKitSim/<device-id>/EMG   --rate Hz
  rsp   NeuroKitSim/<device-id>/RSP   --rate Hz
  ramp  NeuroKitSim/<device-id>/RAMP  --rate Hz, value = sample index (for loss tests)
Sample i of every stream is stamped t0 + i/rate on the LSL clock and sent in real time.

Examples:
  physio_simulator --seconds 60 --signals ecg,hr            # a Polar H10 for one minute
  physio_simulator --continuous --signals ecg,ppg,eda,ramp   # until Ctrl-C
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from typing import Any

from hri_physio_bridge.nodes.common import CliError, fail, install_stop_handlers, load_yaml_conf
from hri_physio_bridge.simulator import (
    OPTION_KEYS,
    SIGNALS,
    Block,
    Pacer,
    RunOptions,
    SampleSource,
    SimulatorConfig,
    make_source,
    options_from_mapping,
    run_paced,
    stream_spec,
)

PROG = "physio_simulator"
PROGRESS_EVERY = 5.0  # seconds between progress lines


def build_parser() -> argparse.ArgumentParser:
    d = SimulatorConfig()
    p = argparse.ArgumentParser(prog=PROG, description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    add = p.add_argument
    add("--conf", metavar="FILE",
        help="YAML file with any of the options below (e.g. 'bpm: 80', 'device_id: X'); flags win")
    add("--seconds", type=float, help=f"seconds to stream; 0 = until stopped (default {d.seconds:g})")
    add("--continuous", action="store_const", const=True, help="stream until stopped (= --seconds 0)")
    add("--rate", type=float, help=f"sampling rate in Hz (default {d.rate:g}, the Polar H10 ECG rate)")
    add("--noise", type=float, help=f"noise amplitude (default {d.noise:g})")
    add("--bpm", type=float, help=f"heart rate for ECG, HR and PPG (default {d.bpm:g})")
    add("--scr", type=int, help=f"skin conductance responses per simulation, EDA (default {d.scr})")
    add("--drift", type=float, help=f"EDA linear drift per second (default {d.drift:g})")
    add("--bnum", type=int, help=f"EMG bursts per simulation (default {d.bnum})")
    add("--bdur", type=float, help=f"EMG burst duration in s (default {d.bdur:g})")
    add("--resp", type=float, help=f"breaths per minute, RSP (default {d.resp:g})")
    add("--seed", type=int, help=f"random seed (default {d.seed})")
    add("--segment-seconds", type=float,
        help=f"continuous mode: length of each generated segment (default {d.segment_seconds:g})")
    add("--signals", help=f"comma list from {','.join(SIGNALS)} (default ecg,hr)")
    add("--device-id", help="device id in the stream names (default SIM0001)")
    add("--name-prefix", help="prefix for every stream name, e.g. for test isolation")
    add("--chunk", type=int, help="samples per push (default: about 0.1 s, 13 at 130 Hz); HR sends 1")
    add("--wait-for-consumers", type=float, metavar="SECONDS",
        help="wait up to this long for an inlet on every stream before streaming (default 0)")
    return p


def resolve_options(args: argparse.Namespace) -> RunOptions:
    """YAML file first, command-line flags on top."""
    values: dict[str, Any] = {}
    if args.conf:
        conf = {str(k).replace("-", "_"): v for k, v in load_yaml_conf(args.conf, PROG).items()}
        unknown = sorted(set(conf) - OPTION_KEYS)
        if unknown:
            raise CliError(f"{args.conf}: unknown option(s) {', '.join(unknown)}; "
                           f"known: {', '.join(sorted(OPTION_KEYS))}")
        values.update(conf)
    values.update({k: v for k, v in vars(args).items() if k != "conf" and v is not None})
    return options_from_mapping(values)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(sys.argv[1:] if argv is None else argv)
    try:
        opts = resolve_options(args)
    except (CliError, ValueError) as exc:
        fail(PROG, str(exc))

    def log(text: str) -> None:
        print(f"[{PROG}] {text}", flush=True)

    stop = install_stop_handlers(lambda name: log(f"{name}: stopping"))
    import pylsl  # after argument checks: --help and bad flags answer without loading liblsl

    from hri_physio_bridge.frames import Frame
    from hri_physio_bridge.streamers.lsl import LslStreamer

    cfg = opts.sim
    sources: dict[str, SampleSource] = {}
    outlets: dict[str, LslStreamer] = {}
    code = 0
    try:
        for sig in opts.signals:
            sources[sig] = make_source(sig, cfg)
            sources[sig].prefetch()  # NeuroKit2 takes a moment: not on the streaming clock
        for sig in opts.signals:
            spec = stream_spec(sig, cfg, opts.device_id, opts.name_prefix)
            outlets[sig] = LslStreamer(spec.name)
            outlets[sig].open_output(spec)
        length = "until stopped" if cfg.continuous else f"{cfg.seconds:g} s"
        log(f"streaming {', '.join(o.name for o in outlets.values())} ({length}, {cfg.rate:g} Hz, "
            f"{cfg.bpm:g} bpm, chunk {opts.chunk_samples}, seed {cfg.seed})")
        if opts.wait_for_consumers > 0:
            _wait_for_consumers(outlets, opts.wait_for_consumers, stop.wait, pylsl.local_clock, log)

        # One clock: the LSL clock stamps the samples and paces them.
        t0 = pylsl.local_clock()
        for src in sources.values():
            src.t0 = t0
        pacer = Pacer(sources, opts.chunk_samples, start=t0)
        next_report = [t0 + PROGRESS_EVERY]

        def emit(sig: str, block: Block) -> None:
            outlets[sig].publish(Frame(block.timestamps, block.values.reshape(-1, 1)))

        def tick(now: float) -> None:
            if now >= next_report[0]:
                next_report[0] += PROGRESS_EVERY
                log(f"{now - t0:.0f} s: sent " + _counts(sources))

        run_paced(pacer, pylsl.local_clock, stop.wait, emit, stop.is_set, tick)
    except Exception as exc:  # one clear line, and the outlets still close
        print(f"{PROG}: error: {type(exc).__name__}: {exc}", file=sys.stderr, flush=True)
        code = 1
    finally:
        for outlet in outlets.values():
            outlet.close()
        log("done: sent " + _counts(sources))
    return code


def _counts(sources: dict[str, SampleSource]) -> str:
    return ", ".join(f"{sig}: {src.sent}" for sig, src in sources.items())


def _wait_for_consumers(outlets: dict[str, Any], timeout: float, wait: Callable[[float], bool],
                        clock: Callable[[], float], log: Callable[[str], None]) -> None:
    """Give receivers a head start so they get the stream from its first sample."""
    deadline = clock() + timeout
    while not all(o.has_consumers() for o in outlets.values()):
        if clock() >= deadline:
            log(f"no consumer on every stream after {timeout:g} s; streaming anyway")
            return
        if wait(0.05):  # stop requested
            return


if __name__ == "__main__":
    sys.exit(main())
