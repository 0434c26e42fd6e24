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

import sys
import threading
from typing import Any

from hri_physio_bridge.node_runner import ManagedNode, logic_logger, run_node
from hri_physio_bridge.simulator import (
    Block,
    Pacer,
    SampleSource,
    SimulatorConfig,
    make_source,
    run_paced,
    stream_spec,
)
from hri_physio_bridge.waiting import wait_for_consumers

PROG = "physio_simulator"
PROGRESS_EVERY = 5.0  # seconds between progress lines


class PhysioSimulatorNode(ManagedNode):
    """Streams the configured signals onto LSL; its options are also ROS parameters."""

    def __init__(self, config: SimulatorConfig, **kwargs: Any) -> None:
        super().__init__(PROG, **kwargs)
        self.config = self.declare_config(config)
        self.log = logic_logger(self.get_name(), self.get_logger())
        self.sources: dict[str, SampleSource] = {}

    def run(self, stop: threading.Event) -> int:
        import pylsl  # here, not at import: --help and bad options answer without loading liblsl

        from hri_physio_bridge.frames import Frame
        from hri_physio_bridge.streamers.lsl import LslStreamer

        cfg, log = self.config, self.log
        outlets: dict[str, LslStreamer] = {}
        code = 0
        try:
            for sig in cfg.signals:
                self.sources[sig] = make_source(sig, cfg)
                self.sources[sig].prefetch()  # NeuroKit2 takes a moment: not on the streaming clock
            for sig in cfg.signals:
                spec = stream_spec(sig, cfg, cfg.device_id, cfg.name_prefix)
                outlets[sig] = LslStreamer(spec.name)
                outlets[sig].open_output(spec)
            length = "until stopped" if cfg.continuous else f"{cfg.seconds:g} s"
            log.info(f"streaming {', '.join(o.name for o in outlets.values())} ({length}, {cfg.rate:g} Hz, "
                     f"{cfg.bpm:g} bpm, chunk {cfg.chunk_samples}, seed {cfg.seed})")
            # Give receivers a head start so they get the streams from their first sample.
            wait_for_consumers(lambda: sum(o.has_consumers() for o in outlets.values()), len(outlets),
                               cfg.wait_for_consumers, what="every simulated stream", log=log,
                               clock=pylsl.local_clock, stop=stop)
            if stop.is_set():
                return 0

            # One clock: the LSL clock stamps the samples and paces them.
            t0 = pylsl.local_clock()
            for src in self.sources.values():
                src.t0 = t0
            pacer = Pacer(self.sources, cfg.chunk_samples, start=t0)
            next_report = [t0 + PROGRESS_EVERY]

            def emit(sig: str, block: Block) -> None:
                outlets[sig].publish(Frame(block.timestamps, block.values.reshape(-1, 1)))

            def tick(now: float) -> None:
                if now >= next_report[0]:
                    next_report[0] += PROGRESS_EVERY
                    log.info(f"{now - t0:.0f} s: sent {self.counts()}")

            run_paced(pacer, pylsl.local_clock, stop.wait, emit, stop.is_set, tick)
        except Exception as exc:  # one clear line, and the outlets still close
            log.error(f"{type(exc).__name__}: {exc}")
            code = 1
        finally:
            for outlet in outlets.values():
                outlet.close()
            log.info(f"done: sent {self.counts()}")
        return code

    def counts(self) -> str:
        return ", ".join(f"{sig}: {src.sent}" for sig, src in self.sources.items())


def main(argv: list[str] | None = None) -> int:
    return run_node(PROG, SimulatorConfig, PhysioSimulatorNode, argv=argv, description=__doc__)


if __name__ == "__main__":
    sys.exit(main())
