"""neurokit_processor: ECG (or PPG, EDA) features per sliding window, from any stream to ROS 2 (+ LSL).

Reads frames from a ROS 2 topic, an LSL stream or a CSV log, windows them (default 60 s
every 5 s), runs NeuroKit2 on each window and publishes, under ``<output_prefix>``:

  ECG  clean, rpeaks, beat_hr (frames); hr, sdnn, rmssd, pnn50, pnn20, lf, hf, lfhf, lfnu, hfnu,
       quality
  PPG  clean, peaks, beat_hr (frames);  the same scalars
  EDA  clean, scr_peaks (frames);        tonic, scr_count, scr_amplitude
  status (std_msgs/String JSON with "t"): window extent, flags, why a feature is NaN, beats
       (detected, corrected as artefacts, beat-free stretches)

Scalars are one-sample frames [t, value] stamped with the end of their window. A CSV input
that does not exist is an error at once (exit 1); an LSL stream or ROS topic that is not
there yet is waited for until it appears or the node is stopped.

Examples::

    neurokit_processor --input ros:/physio/polar_h10/ecg
    neurokit_processor --input lsl:PolarH10/SIM0001/ECG --output-prefix /physio/polar_h10/ecg
    neurokit_processor --conf processor.yaml
    neurokit_processor --ros-args --params-file params.yaml
"""

from __future__ import annotations

import json
import sys
import threading
from typing import Any

from std_msgs.msg import String

from hri_physio_bridge.node_runner import ManagedNode, logic_logger, run_node
from hri_physio_bridge.qos import event_qos
from hri_physio_bridge.ros_tools import wait_all_acked
from hri_physio_bridge.streamers import Streamer, StreamerError, StreamSpec, create_streamer
from hri_physio_bridge.streamers.lsl import LINGER, LslStreamer
from hri_physio_bridge.streamers.ros import RosStreamer
from hri_physio_processing.config import ProcessorConfig
from hri_physio_processing.features import SCALARS, SIGNAL_FEATURES
from hri_physio_processing.pipeline import ProcessingPipeline
from hri_physio_processing.processor import FrameOutput, Output, StatusOutput

PROG = "neurokit_processor"
#: Outputs at the input's sampling rate (the rest are one value per window).
_SAMPLE_RATE_OUTPUTS = ("clean", "rpeaks", "peaks", "scr_peaks")


class NeurokitProcessorNode(ManagedNode):
    """ROS 2 shell around :class:`ProcessingPipeline`: parameters, input streamer, output publishers."""

    def __init__(self, config: ProcessorConfig, **kwargs: Any) -> None:
        super().__init__(PROG, **kwargs)
        self.config = cfg = self.declare_config(config)
        self.prefix = cfg.resolved_output_prefix()
        self.log = logic_logger(self.get_name(), self.get_logger())
        self.outputs: dict[str, list[Streamer]] = {}
        self.status_pub = self.create_publisher(String, f"{self.prefix}/status", event_qos())
        self._open_outputs()
        # A ros: input's callback only queues the frame; the pipeline processes on the main thread.
        source = create_streamer(cfg.input, node=self, max_chunk=max(1, cfg.hop_samples),
                                 depth=cfg.input_depth)
        self.pipeline = ProcessingPipeline(cfg, source, self.emit, self.log, consumers=self.consumer_count,
                                           outputs_label=self.prefix)

    def _open_outputs(self) -> None:
        cfg = self.config
        lsl_prefix = cfg.resolved_lsl_prefix()
        for feature in (*SIGNAL_FEATURES[cfg.mode], *SCALARS[cfg.mode]):
            rate = cfg.sampling_rate if feature in _SAMPLE_RATE_OUTPUTS else 0.0
            topic = f"{self.prefix}/{feature}"
            ros = create_streamer(f"ros:{topic}", node=self)
            ros.open_output(StreamSpec(name=topic, nominal_rate=rate, channels=(feature,)))
            sinks: list[Streamer] = [ros]
            if cfg.lsl_output:
                name = f"{lsl_prefix}/{feature}"
                lsl = create_streamer(f"lsl:{name}")
                lsl.open_output(StreamSpec(
                    name=name, type=f"{cfg.mode.upper()}-{feature}", nominal_rate=rate,
                    source_id=f"{PROG}{name}", channels=(feature,),
                ))
                sinks.append(lsl)
            self.outputs[feature] = sinks

    def consumer_count(self) -> int:
        """Listeners on the least-listened ROS output (the status topic included)."""
        counts = [sinks[0].consumer_count() for sinks in self.outputs.values()]
        return min([*counts, self.status_pub.get_subscription_count()])

    def emit(self, out: Output) -> None:
        if isinstance(out, FrameOutput):
            for sink in self.outputs[out.feature]:
                sink.publish(out.frame)
        elif isinstance(out, StatusOutput):
            self.status_pub.publish(String(data=json.dumps(out.payload, allow_nan=False)))

    def run(self, stop: threading.Event) -> int:
        code = self.pipeline.run(stop)
        if self.pipeline.processor.stats.samples_in:
            stats = {**self.pipeline.processor.stats.as_dict(), "input": self.pipeline.input_state()}
            self.get_logger().info(f"done: {json.dumps(stats)}")
        return code

    def close(self) -> None:
        self.pipeline.source.close()
        sinks = [sink for feature_sinks in self.outputs.values() for sink in feature_sinks]
        # The last frames of every ROS output (and the status) acknowledged, within one second for all.
        wait_all_acked([*(s.publisher for s in sinks if isinstance(s, RosStreamer)), self.status_pub], 1.0)
        lingered = False
        for sink in sinks:
            if isinstance(sink, RosStreamer):
                sink.close(ack_timeout=0.0)
            elif isinstance(sink, LslStreamer):
                # liblsl has no flush: one short linger gives every outlet's inlets their last chunk.
                listened = sink.has_consumers()
                sink.close(linger=0.0 if lingered else LINGER)
                lingered = lingered or listened
            else:
                sink.close()
        self.outputs.clear()


def main(argv: list[str] | None = None) -> int:
    return run_node(
        PROG, ProcessorConfig, NeurokitProcessorNode, argv=argv, startup_errors=(StreamerError, ValueError),
        description=__doc__, epilog="The seed's --conf keys buffer (samples per window) and window "
        "(samples kept for the next window) are translated to window_seconds and hop_seconds.",
    )


if __name__ == "__main__":
    sys.exit(main())
