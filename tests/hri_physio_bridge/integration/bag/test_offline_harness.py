"""The offline harness on the bridge: a live session, recorded, replayed into the same node.

Live: physio_simulator (LSL, 130 Hz ECG) -> physio_receiver ``rx_live`` (LSL -> ROS /ecg,
held until its two readers, the recorder and rx_window, are both matched) ->
physio_receiver ``rx_window`` (ROS -> ROS sliding windows, /ecg -> /ecg_win), while the
recorder records both /ecg (the window node's input) and /ecg_win (its output). Then:

1. the bag is replayed to a subscriber: every frame and every sample timestamp of /ecg
   comes back bit for bit;
2. the recorded /ecg is replayed, twice, into fresh ``rx_window`` nodes: each run's /ecg_win
   must equal the *live* /ecg_win frame by frame (channels, sample timestamps, values), and
   the windows hold exactly the simulated samples.
"""

from __future__ import annotations

import uuid
from pathlib import Path

import numpy as np
import pytest

from helpers import NodeProcess, RosFrameCollector, concat_new_samples, wait_until
from helpers.offline_harness import NodeSpec, OfflineHarness
from hri_physio_bridge.frames import Frame
from hri_physio_bridge.ros_frames import msg_to_frame

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


def test_live_window_output_is_reproduced_by_replay(tmp_path: Path, lsl_name: str, ros_context) -> None:

    uid = uuid.uuid4().hex[:8]
    ecg, win = f"/harness_{uid}/ecg", f"/harness_{uid}/ecg_win"
    h = OfflineHarness(tmp_path)

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
            publishes=(win,),
        )

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
            # /ecg has two readers, the recorder and rx_window: only once both are matched does
            # rx_live read its input, so each of them sees every frame (see offline_harness)
            "--min-consumers",
            "2",
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
    live = h.record("live", [ecg, win], [rx_window(), rx_live, sim])

    # the live input: every simulated sample reached the bag, once, in order, evenly spaced
    frames = [f for _, f in h.decoded(live, ecg, _frame)]
    ts, vs = concat_new_samples(frames, 13, 0)
    assert len(ts) == int(RATE * SECONDS), h.logs
    np.testing.assert_allclose(np.diff(ts), 1 / RATE, rtol=1e-6)
    assert all(f.num_channels == 1 for f in frames)
    # the live output: rx_window ran in the live session and windowed exactly those samples
    live_windows = [f for _, f in h.decoded(live, win, _frame)]
    assert len(live_windows) >= len(ts) // 15, h.logs
    wts, wvs = concat_new_samples(live_windows, 20, 5)
    np.testing.assert_array_equal(wts, ts)
    np.testing.assert_array_equal(wvs, vs)

    # (1) replay to a subscriber: every input frame and timestamp round-trips, bit for bit
    collector = RosFrameCollector(ros_context, f"harness_{uid}")
    try:
        got = collector.subscribe_frames(ecg)
        with NodeProcess(
            "replayer",
            str(live),
            "--rate",
            "5",
            "--topics",
            ecg,
            "--wait-for-subscribers",
            "30",
            "--delay",
            "0.3",
        ) as player:
            assert player.wait(60) == 0, player.output
        wait_until(lambda: len(got) == len(frames), 10, lambda: f"{len(got)}/{len(frames)} frames")
    finally:
        collector.close()
    for have, want in zip(got, frames, strict=True):
        assert _same_frame(have, want)

    # (2) the recorded input into fresh rx_window nodes, twice: each reproduces the live output
    for run in ("replay1", "replay2"):
        out = h.replay(run, live, [ecg], [rx_window()], [win])
        n = h.assert_same(live, out, {win: win}, _frame, _same_frame)
        assert n == len(live_windows), (run, n, len(live_windows))
