"""Benchmark the recorder node against writing the same bytes with the rosbags Writer alone.

Two streams, each offered at its nominal rate for --seconds (default 10):

* ``frames``: 64 channels x 1 kHz as Float64MultiArray frames of --frame samples (default 10,
  i.e. 100 frames/s of 10 x 65 doubles, the layout of DESIGN.md);
* ``strings``: 10 000 small std_msgs/String messages per second.

A publisher in this process paces the stream; the recorder runs as a subprocess (its
CPU% and peak RSS come from /proc via psutil). Afterwards the bag's messages are written
again, as fast as possible, with ``rosbags.rosbag2.Writer`` (MCAP, zstd chunks) alone and
with our ``BagWriter`` alone. Reported per stream:

* recorder: messages/s and MB/s recorded, messages lost, CPU%, peak RSS;
* ratio = recorder's sustained rate / min(offered rate, rosbags Writer alone's max rate):
  how close the live recorder comes to what the storage library alone could write for
  the same offered stream (goal >= 0.8);
* for information: the max rates of rosbags Writer alone and BagWriter alone, and the
  recorder's own ceiling (the same stream published as fast as possible, --burst).

Run:  source scripts/env.sh; python bench/bench_recorder.py [--seconds 10] [--burst]
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import psutil

from hri_physio_bridge.bag.reader import BagReader


@dataclass
class Stream:
    name: str
    msg_type: str
    rate: float  # messages per second offered

    def messages(self, frame: int) -> list:
        from std_msgs.msg import String

        from hri_physio_bridge.frames import Frame, frame_to_msg

        if self.name == "strings":
            return [String(data=f'{{"t": {i / self.rate:.6f}, "event": "tick {i}"}}') for i in range(1000)]
        rng = np.random.default_rng(1)
        t = np.arange(frame) / 1000.0
        return [frame_to_msg(Frame(t + i * frame / 1000.0, rng.normal(size=(frame, 64)))) for i in range(50)]


@dataclass
class RecorderResult:
    published: int
    recorded: int
    seconds: float
    payload_bytes: int
    cpu_percent: float
    peak_rss_mb: float

    @property
    def rate(self) -> float:
        return self.recorded / self.seconds if self.seconds > 0 else 0.0

    @property
    def mbps(self) -> float:
        return self.payload_bytes / self.seconds / 1e6 if self.seconds > 0 else 0.0


def _peak_rss_mb(proc: psutil.Process) -> float:
    try:
        for line in Path(f"/proc/{proc.pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return proc.memory_info().rss / 1e6


def run_recorder(
    stream: Stream, seconds: float, frame: int, burst: bool, workdir: Path
) -> tuple[RecorderResult, Path]:
    import rclpy
    from rclpy.node import Node
    from rclpy.qos import QoSProfile
    from rclpy.subscription import RCLError
    from std_msgs.msg import Float64MultiArray, String

    topic = f"/bench_{uuid.uuid4().hex[:6]}/{stream.name}"
    bag = workdir / f"{stream.name}{'_burst' if burst else ''}"
    rec = subprocess.Popen(
        [
            str(Path(sys.prefix) / "bin" / "recorder"),
            topic,
            "-o",
            str(bag),
            "--discovery-period",
            "0.2",
            "--status-period",
            "2",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env=dict(os.environ),
    )
    ps = psutil.Process(rec.pid)
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = Node(f"bench_pub_{uuid.uuid4().hex[:6]}", context=ctx)
    cls = String if stream.name == "strings" else Float64MultiArray
    pub = node.create_publisher(cls, topic, QoSProfile(depth=1000))
    msgs = stream.messages(frame)
    deadline = time.monotonic() + 30
    while pub.get_subscription_count() == 0:
        if time.monotonic() > deadline or rec.poll() is not None:
            raise SystemExit(f"recorder did not subscribe to {topic}")
        time.sleep(0.05)
    time.sleep(0.5)
    cpu0 = ps.cpu_times()
    t0 = time.monotonic()
    sent = 0
    period = 1.0 / stream.rate
    while True:
        now = time.monotonic()
        if now - t0 >= seconds:
            break
        due = sent + 100 if burst else int((now - t0) * stream.rate) + 1  # what is due by now
        while sent < due:
            try:
                pub.publish(msgs[sent % len(msgs)])
            except RCLError:  # reliable history full: the reader is behind
                time.sleep(0.001)
                continue
            sent += 1
        if not burst:
            time.sleep(min(0.001, max(0.0, t0 + sent * period - time.monotonic())))
    elapsed = time.monotonic() - t0
    time.sleep(1.0)  # let the recorder drain its queue
    cpu1 = ps.cpu_times()
    cpu = (cpu1.user + cpu1.system - cpu0.user - cpu0.system) / (elapsed + 1.0) * 100
    rss = _peak_rss_mb(ps)
    rec.send_signal(signal.SIGINT)
    rec.wait(30)
    node.destroy_node()
    rclpy.shutdown(context=ctx)
    reader = BagReader(bag)
    times = [m.log_time_ns for m in reader.messages()]
    payload = sum(len(m.data) for m in reader.messages())
    span = (times[-1] - times[0]) / 1e9 if len(times) > 1 else elapsed
    return RecorderResult(sent, len(times), max(span, 1e-9) if burst else elapsed, payload, cpu, rss), bag


def writer_alone(bag: Path, workdir: Path, which: str) -> tuple[float, float]:
    """Max msgs/s and MB/s writing the bag's messages again with one storage writer only."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

    reader = BagReader(bag)
    msgs = [(m.topic, m.log_time_ns, m.data) for m in reader.messages()]
    info = next(iter(reader.topics.values()))
    from hri_physio_bridge.bag.msgdefs import message_definition

    msgdef = message_definition(info.type)
    out = workdir / f"alone_{which}_{uuid.uuid4().hex[:6]}"
    t0 = time.perf_counter()
    if which == "rosbags":
        w = Writer(out, version=9, storage_plugin=StoragePlugin.MCAP)
        w.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        w.open()
        conn = w.add_connection(info.name, info.type, msgdef=msgdef, rihs01=info.type_description_hash)
        for _topic, t, data in msgs:
            w.write(conn, t, data)
        w.close()
    else:
        from hri_physio_bridge.bag.writer import BagWriter

        bw = BagWriter(out)
        bw.add_topic(info.name, info.type, msgdef, info.type_description_hash, info.offered_qos_profiles)
        for topic, t, data in msgs:
            bw.write(topic, t, data)
        bw.close()
    dt = time.perf_counter() - t0
    return len(msgs) / dt, sum(len(d) for _, _, d in msgs) / dt / 1e6


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--frame", type=int, default=10, help="samples per 64-channel frame (default 10)")
    ap.add_argument(
        "--burst", action="store_true", help="also measure the recorder's ceiling (as fast as possible)"
    )
    ap.add_argument("--only", choices=("frames", "strings"), help="run one stream only")
    args = ap.parse_args()
    streams = [
        Stream("frames", "std_msgs/msg/Float64MultiArray", 1000.0 / args.frame),
        Stream("strings", "std_msgs/msg/String", 10_000.0),
    ]
    with tempfile.TemporaryDirectory(prefix="bench_recorder_") as tmp:
        work = Path(tmp)
        for s in streams:
            if args.only and s.name != args.only:
                continue
            res, bag = run_recorder(s, args.seconds, args.frame, False, work)
            rb_rate, rb_mbps = writer_alone(bag, work, "rosbags")
            bw_rate, bw_mbps = writer_alone(bag, work, "ours")
            ratio = res.rate / min(s.rate, rb_rate)
            print(f"\n== {s.name}: offered {s.rate:.0f} msg/s for {args.seconds:g} s ==")
            print(
                f"recorder:           {res.rate:10.0f} msg/s {res.mbps:8.2f} MB/s  recorded {res.recorded}/"
                f"{res.published} (lost {res.published - res.recorded}), CPU {res.cpu_percent:.0f}%, "
                f"peak RSS {res.peak_rss_mb:.0f} MB"
            )
            print(f"rosbags Writer alone (max): {rb_rate:10.0f} msg/s {rb_mbps:8.2f} MB/s")
            print(f"BagWriter alone (max):      {bw_rate:10.0f} msg/s {bw_mbps:8.2f} MB/s")
            print(f"ratio recorder / min(offered, rosbags Writer): {ratio:.2f}  (goal >= 0.8)")
            if args.burst:
                burst, _ = run_recorder(s, min(args.seconds, 5.0), args.frame, True, work)
                print(
                    f"recorder ceiling (burst):   {burst.rate:10.0f} msg/s {burst.mbps:8.2f} MB/s  recorded "
                    f"{burst.recorded}/{burst.published}, CPU {burst.cpu_percent:.0f}%; "
                    f"vs rosbags Writer alone max: {burst.rate / rb_rate:.2f}"
                )
            sys.stdout.flush()
    return 0


if __name__ == "__main__":
    threading.current_thread().name = "bench"
    sys.exit(main())
