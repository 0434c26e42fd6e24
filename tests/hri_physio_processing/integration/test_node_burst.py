"""neurokit_processor under a burst: a ros: input faster than processing loses nothing, and when
its queue is made too small, every lost frame is counted and reported (never silent).

Real node (subprocess, real rclpy): frames of 13 samples (as physio_receiver publishes the Polar
ECG) are published as fast as rclpy can, far faster than the processor can window them.
"""

from __future__ import annotations

import signal
import time
from collections.abc import Callable

import numpy as np
import pytest

from helpers import NEUROKIT_START, NodeProcess, wait_until
from helpers.processing import Outputs

pytestmark = pytest.mark.ros
FS = 130
FRAME = 13


def burst(ros_context, topic: str, t: np.ndarray, x: np.ndarray, paced_tail: int = 0,
          first_window: Callable[[], bool] | None = None, warm_up: int = 0) -> None:
    """Every frame at once; ``warm_up`` samples first (paced, then ``first_window()`` waited for: the
    processor has taken frames before the burst), and the last ``paced_tail`` samples at 20 frames/s
    (a stretch that fits even a small queue on a loaded machine, so the input ends with whole windows)."""
    from rclpy.duration import Duration
    from rclpy.node import Node
    from std_msgs.msg import Float64MultiArray

    from hri_physio_bridge.frames import Frame
    from hri_physio_bridge.qos import frame_qos
    from hri_physio_bridge.ros_frames import frame_to_msg

    node = Node("ecg_burst", context=ros_context)
    pub = node.create_publisher(Float64MultiArray, topic, frame_qos())  # as physio_receiver's output
    try:
        wait_until(lambda: pub.get_subscription_count() > 0, NEUROKIT_START, "the processor's subscription")
        tail = t.shape[0] - paced_tail
        for a in range(0, t.shape[0], FRAME):
            if a < warm_up:
                time.sleep(0.01)
            elif a == warm_up and warm_up and first_window is not None:
                wait_until(first_window, 60, "the processor's first window (it took the warm-up's frames)")
            if a >= tail:
                time.sleep(0.05)
            pub.publish(frame_to_msg(Frame(t[a : a + FRAME], x[a : a + FRAME].reshape(-1, 1))))
        # Bounded: a reliable writer whose reader dropped samples from its full queue may never see them
        # all acknowledged (what arrived is proven by the counts, not by the acknowledgements).
        pub.wait_for_all_acked(Duration(seconds=10))
    finally:
        node.destroy_node()


def events(out: Outputs, kind: str) -> list[dict]:
    with out._lock:
        return [s for s in out.status if s.get("event") == kind]


def run_burst(ros_context, collector, lsl_name: str, mitdb, seconds: int, *args: str,
              paced_tail: int = 0, warm_up: int = 0) -> tuple[Outputs, dict, np.ndarray]:
    tag = lsl_name.split("/")[0]
    topic, prefix = f"/test/{tag}/burst_in", f"/test/{tag}/burst"
    n = seconds * FS
    t, x = 4000.0 + mitdb.t[:n], mitdb.x[:n]
    out = Outputs(collector, prefix)
    with NodeProcess("neurokit_processor", "--input", f"ros:{topic}", "--output-prefix", prefix,
                     "--quality-method", "none", "--wait-for-consumers", "30", *args) as proc:
        burst(ros_context, topic, t, x, paced_tail, lambda: bool(out.windows()), warm_up)
        # The newest frames are never the ones lost: wait until a window reaches the end of the input.
        wait_until(lambda: any(w["window"]["t_end"] >= t[-1] - 5.0 for w in out.windows()), 300,
                   lambda: f"a window at the end of the input; node said:\n{proc.output[-3000:]}")
        assert proc.stop(signal.SIGINT) == 0, proc.output[-3000:]
        wait_until(lambda: events(out, "stopped"), 20, "the stopped event")
    return out, events(out, "stopped")[0], t


def test_a_burst_faster_than_processing_reaches_the_pipeline_whole(ros_context, collector, lsl_name: str,
                                                                   mitdb) -> None:
    # 3000 frames at once: three times the subscription queue the processor had (1000 frames).
    out, stopped, t = run_burst(ros_context, collector, lsl_name, mitdb, 300)
    assert stopped["ok"] and stopped["input"]["dropped_frames"] == 0, stopped
    assert stopped["input"]["samples_in"] == t.shape[0]  # every sample reached the pipeline
    assert events(out, "discontinuity") == [] and events(out, "input_lost") == []
    wins = out.windows()
    ends = [t[(60 + 5 * k) * FS - 1] for k in range(49)]
    assert [w["window"]["t_end"] for w in wins] == pytest.approx(ends)
    clean_t, _ = out.joined("clean")
    np.testing.assert_array_equal(clean_t, t)  # the windows cover the whole input, each sample once


def test_frames_lost_to_a_too_small_queue_are_counted_and_reported(ros_context, collector, lsl_name: str,
                                                                   mitdb) -> None:
    # A first window's worth of frames paced (the processor has taken its first frame before anything is
    # lost, so every loss shows as a skip in the publisher's sequence numbers), then 1100 frames at once
    # into a queue of 10, then 15 s paced so that the input ends with whole windows.
    out, stopped, t = run_burst(ros_context, collector, lsl_name, mitdb, 150, "--input-depth", "10",
                                "--window-seconds", "10", "--hop-seconds", "5", paced_tail=15 * FS,
                                warm_up=10 * FS)
    dropped = stopped["input"]["dropped_frames"]
    assert dropped > 0 and not stopped["ok"]
    # Every frame is accounted for: processed, counted as lost, or (stopped first) counted as queued.
    accounted = stopped["input"]["samples_in"] + FRAME * (dropped + stopped["input"]["backlog"])
    assert accounted == t.shape[0], stopped
    lost = events(out, "input_lost")
    assert lost and 0 < lost[0]["dropped_frames"] <= dropped
    assert events(out, "discontinuity")  # the holes show as gaps, windows restart after them
    assert all(w["input"]["dropped_frames"] <= dropped for w in out.windows())
