"""The offline harness on the bridge: simulated ECG -> physio_receiver -> bag -> replay.

Live: physio_simulator (LSL, 130 Hz ECG) -> physio_receiver (LSL -> /ecg) while the recorder
records /ecg. Then the bag is (1) replayed to a subscriber: every frame and every sample
timestamp must come back bit for bit; (2) replayed twice into a fresh physio_receiver
(ROS -> ROS sliding windows): both runs' outputs must be identical, and the windows must
hold exactly the recorded samples.
"""

from __future__ import annotations

import uuid
from pathlib import Path

import numpy as np
import pytest
from offline_harness import NodeSpec, OfflineHarness

from helpers import RosFrameCollector, concat_new_samples, wait_until
from hri_physio_bridge.frames import Frame, msg_to_frame

pytestmark = [pytest.mark.ros, pytest.mark.lsl]
RATE = 130.0
SECONDS = 3


def _frame(data: bytes) -> Frame:
    from rclpy.serialization import deserialize_message
    from std_msgs.msg import Float64MultiArray

    return msg_to_frame(deserialize_message(data, Float64MultiArray))


def _same_frame(a: Frame, b: Frame) -> bool:
    return (
        a.channels == b.channels
        and np.array_equal(a.timestamps, b.timestamps)
        and np.array_equal(a.values, b.values)
    )


def test_receiver_output_round_trips_and_replays_deterministically(
    tmp_path: Path, lsl_name: str, ros_context
) -> None:
    uid = uuid.uuid4().hex[:8]
    ecg, win = f"/harness_{uid}/ecg", f"/harness_{uid}/ecg_win"
    h = OfflineHarness(tmp_path)
    rx_live = NodeSpec(
        "physio_receiver",
        (
            "--input",
            f"lsl:{lsl_name}/PolarH10/SIM0001/ECG",
            "--output",
            f"ros:{ecg}",
            "--num-channels",
            "1",
            "--output-frame",
            "13",
            "--sampling-rate",
            str(RATE),
            "--resolve-timeout",
            "60",
            "--wait-for-consumers",
            "60",
        ),
    )
    sim = NodeSpec(
        "physio_simulator",
        (
            "--seconds",
            str(SECONDS),
            "--signals",
            "ecg",
            "--rate",
            str(RATE),
            "--name-prefix",
            lsl_name,
            "--wait-for-consumers",
            "60",
        ),
        runs_to_end=True,
    )
    live = h.record("live", [ecg], [rx_live, sim])

    # the live leg: every simulated sample reached the bag, once, in order, evenly spaced
    frames = [f for _, f in h.decoded(live, ecg, _frame)]
    ts, vs = concat_new_samples(frames, 13, 0)
    assert len(ts) == int(RATE * SECONDS), h.logs
    np.testing.assert_allclose(np.diff(ts), 1 / RATE, rtol=1e-6)
    assert all(f.num_channels == 1 for f in frames)

    # (1) replay to a subscriber: every frame and timestamp round-trips, bit for bit
    collector = RosFrameCollector(ros_context, f"harness_{uid}")
    try:
        got = collector.subscribe_frames(ecg)
        from helpers import NodeProcess

        with NodeProcess(
            "replayer", str(live), "--rate", "5", "--wait-for-subscribers", "30", "--delay", "0.3"
        ) as player:
            assert player.wait(60) == 0, player.output
        wait_until(lambda: len(got) == len(frames), 10, lambda: f"{len(got)}/{len(frames)} frames")
    finally:
        collector.close()
    for have, want in zip(got, frames, strict=True):
        assert _same_frame(have, want)

    # (2) replay into fresh nodes, twice: identical outputs, holding exactly the recorded samples
    def rx_window() -> NodeSpec:
        return NodeSpec(
            "physio_receiver",
            (
                "--input",
                f"ros:{ecg}",
                "--output",
                f"ros:{win}",
                "--num-channels",
                "1",
                "--output-frame",
                "20",
                "--sample-overlap",
                "5",
                "--sampling-rate",
                str(RATE),
                "--wait-for-consumers",
                "60",
            ),
            ready="connected",
        )

    run1 = h.replay("replay1", live, [ecg], [rx_window()], [win])
    run2 = h.replay("replay2", live, [ecg], [rx_window()], [win])
    n = h.assert_same(run1, run2, {win: win}, _frame, _same_frame)
    windows = [f for _, f in h.decoded(run1, win, _frame)]
    assert n == len(windows) >= len(ts) // 15
    wts, wvs = concat_new_samples(windows, 20, 5)
    np.testing.assert_array_equal(wts, ts)
    np.testing.assert_array_equal(wvs, vs)
