"""Benchmark the recorder node against writing the same bytes with the rosbags Writer alone.

Two streams:

* ``frames``: 64 channels x 1 kHz as Float64MultiArray frames of --frame samples (default 10,
  i.e. 100 frames/s of 10 x 65 doubles, the layout of DESIGN.md);
* ``strings``: 10 000 small std_msgs/String messages per second.

For each stream the recorder runs as a subprocess (CPU% and peak RSS from /proc via psutil)
while a publisher in this process sends pre-serialized messages (reliable, depth 1000), twice:

(a) offered rate: the stream at its nominal rate for --seconds; reports what the recorder
    recorded, messages/s, MB/s, messages lost, CPU% and peak RSS;
(b) flat out: the same messages published as fast as possible for --burst-seconds. The
    recorder's throughput is what it wrote while saturated: from its own progress reports
    (every 0.25 s, wall-stamped), the messages and payload bytes written between the first and
    the last report of the busy period over the time between them (the receive stamps in the
    bag would not do: a backlog taken after the publisher stopped carries earlier stamps). It
    is compared with ``rosbags.rosbag2.Writer`` alone (MCAP, zstd chunks, in this process)
    writing the very messages the recorder recorded: ratio = recorder msg/s / rosbags Writer
    msg/s (same bytes, so about the same ratio in MB/s), goal >= 0.8. Our ``BagWriter`` alone is
    shown for information. When the recorder took every message sent, the publisher was the
    bottleneck and the recorder's true ceiling is higher than measured (the line says so).
(c) flat out again with the least a Python recorder can do (bench/minimal_recorder.py: one raw
    rclpy subscription -> rosbags Writer): how much of (b)'s gap is receiving through rclpy,
    and the recorder's own overhead over that baseline.
(d) the ceilings of this machine: the rclpy publisher's flat-out send rate, and a receiver that
    takes the raw messages as the recorder does but writes nothing (minimal_recorder.py
    take-only). No rclpy recorder can beat the lower of the two; it is printed as a ratio of
    the Writer alone, with the recorder's share of it.

Run:  source scripts/env.sh; python bench/bench_recorder.py [--quick] [--only frames|strings]
(default about 1 minute per stream; --quick about half of that).
"""

from __future__ import annotations

import argparse
import os
import re
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

GOAL = 0.8


@dataclass
class Stream:
    name: str
    msg_type: str
    rate: float  # messages per second offered

    def payloads(self, frame: int) -> list[bytes]:
        """A cycle of serialized (CDR) messages: the publisher sends bytes, so its own
        serialization does not limit the flat-out run."""
        from rclpy.serialization import serialize_message
        from std_msgs.msg import String

        from hri_physio_bridge.frames import Frame
        from hri_physio_bridge.ros_frames import frame_to_msg

        if self.name == "strings":
            msgs = [String(data=f'{{"t": {i / self.rate:.6f}, "event": "tick {i}"}}') for i in range(1000)]
        else:
            rng = np.random.default_rng(1)
            t = np.arange(frame) / 1000.0
            msgs = [
                frame_to_msg(Frame(t + i * frame / 1000.0, rng.normal(size=(frame, 64)))) for i in range(50)
            ]
        return [serialize_message(m) for m in msgs]


STATUS_RE = re.compile(
    r"^\[INFO\] \[(\d+\.\d+)\] \[(?:physio_)?recorder\]: .*?; (\d+) messages, ([\d.]+) MB payload", re.M
)


def busy_throughput(log: str) -> tuple[int, float, float]:
    """``(messages, MB, seconds)`` written between the first and the last progress report of
    the busy period (reports after the count stopped growing are left out)."""
    reports = [(float(t), int(n), float(mb)) for t, n, mb in STATUS_RE.findall(log)]
    growing = [i for i in range(1, len(reports)) if reports[i][1] > reports[i - 1][1]]
    if len(growing) < 3:
        raise SystemExit(
            f"too few progress reports while busy ({len(growing)}); run longer (--burst-seconds)"
        )
    # from the end of the first busy interval (which started idle) to the end of the
    # second-to-last one (the last one ended idle): full intervals only
    (t0, n0, mb0), (t1, n1, mb1) = reports[growing[0]], reports[growing[-2]]
    return n1 - n0, mb1 - mb0, t1 - t0


@dataclass
class RecorderResult:
    published: int
    recorded: int
    seconds: float  # offered: publishing time; flat out: the busy period of busy_throughput()
    payload_bytes: int  # flat out: written in the busy period
    cpu_percent: float
    peak_rss_mb: float
    busy_messages: int = 0  # flat out: written in the busy period (recorded: all of them)
    sent_rate: float = 0.0  # messages/s the publisher managed

    @property
    def lost(self) -> int:
        return self.published - self.recorded

    @property
    def rate(self) -> float:
        n = self.busy_messages or self.recorded
        return n / self.seconds if self.seconds > 0 else 0.0

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
    stream: Stream,
    payloads: list[bytes],
    seconds: float,
    burst: bool,
    workdir: Path,
    baseline: str | None = None,
) -> tuple[RecorderResult, Path]:
    """Record ``stream`` published for ``seconds`` (at its rate, or as fast as possible), with
    the recorder node or a baseline of bench/minimal_recorder.py (``baseline`` "write" or
    "take-only": then nothing is recorded and only the progress reports count)."""
    import rclpy
    from rclpy.node import Node
    from rclpy.qos import QoSProfile
    from rclpy.subscription import RCLError
    from std_msgs.msg import Float64MultiArray, String

    topic = f"/bench_{uuid.uuid4().hex[:6]}/{stream.name}"
    bag = workdir / f"{stream.name}{'_burst' if burst else ''}{'_' + baseline if baseline else ''}"
    log_path = workdir / f"{bag.name}.log"  # a file, not a pipe: nothing blocks on a full pipe
    log_file = log_path.open("w")
    status_period = "0.25" if burst else "2"
    if baseline:
        argv = [sys.executable, str(Path(__file__).with_name("minimal_recorder.py")), topic, stream.msg_type,
                str(bag), status_period, baseline]
    else:
        argv = [str(Path(sys.prefix) / "bin" / "physio_recorder"), topic, "-o", str(bag),
                "--discovery-period", "0.2", "--status-period", status_period]
    rec = subprocess.Popen(
        argv,
        stdout=subprocess.DEVNULL,
        stderr=log_file,
        env=dict(os.environ),
    )
    ps = psutil.Process(rec.pid)
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = Node(f"bench_pub_{uuid.uuid4().hex[:6]}", context=ctx)
    try:
        cls = String if stream.name == "strings" else Float64MultiArray
        pub = node.create_publisher(cls, topic, QoSProfile(depth=1000))
        deadline = time.monotonic() + 30
        while pub.get_subscription_count() == 0:
            if time.monotonic() > deadline or rec.poll() is not None:
                rec.kill()
                rec.wait()
                raise SystemExit(f"recorder did not subscribe to {topic}: {log_path.read_text()[-2000:]}")
            time.sleep(0.05)
        time.sleep(0.5)
        cpu0 = ps.cpu_times()
        t0 = time.monotonic()
        sent = 0
        n = len(payloads)
        while True:
            now = time.monotonic()
            if now - t0 >= seconds:
                break
            due = sent + 200 if burst else int((now - t0) * stream.rate) + 1  # what is due by now
            while sent < due:
                try:
                    pub.publish(payloads[sent % n])
                except RCLError:  # reliable history full: the reader is behind
                    time.sleep(0.001)
                    continue
                sent += 1
            if not burst:
                time.sleep(min(0.001, max(0.0, t0 + sent / stream.rate - time.monotonic())))
        elapsed = time.monotonic() - t0
        time.sleep(1.0)  # let the recorder drain its queue
        cpu1 = ps.cpu_times()
        cpu = (cpu1.user + cpu1.system - cpu0.user - cpu0.system) / (elapsed + 1.0) * 100
        rss = _peak_rss_mb(ps)
        rec.send_signal(signal.SIGINT)
        if rec.wait(60) != 0:
            raise SystemExit(f"recorder exited with {rec.returncode}: {log_path.read_text()[-2000:]}")
    finally:
        if rec.poll() is None:
            rec.kill()
            rec.wait()
        log_file.close()
        node.destroy_node()
        rclpy.shutdown(context=ctx)
    err = log_path.read_text()
    recorded, payload = 0, 0
    for m in BagReader(bag).messages():
        recorded += 1
        payload += len(m.data)
    if not burst:
        return RecorderResult(sent, recorded, elapsed, payload, cpu, rss, sent_rate=sent / elapsed), bag
    busy_n, busy_mb, busy_s = busy_throughput(err)
    return RecorderResult(
        sent, recorded, busy_s, round(busy_mb * 1e6), cpu, rss, busy_n, sent_rate=sent / elapsed
    ), bag


def writer_alone(bag: Path, workdir: Path, which: str) -> tuple[float, float]:
    """Max msgs/s and MB/s writing the bag's messages again with one storage writer only."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

    from hri_physio_bridge.bag.msgdefs import message_definition

    reader = BagReader(bag)
    msgs = [(m.topic, m.log_time_ns, m.data) for m in reader.messages()]
    info = next(iter(reader.topics.values()))
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


def bench_stream(s: Stream, frame: int, seconds: float, burst_seconds: float, work: Path) -> tuple[str, ...]:
    payloads = s.payloads(frame)
    size = sum(len(p) for p in payloads) / len(payloads)
    print(f"\n== {s.name}: {s.msg_type}, {size:.0f} B per message ==", flush=True)

    res, _ = run_recorder(s, payloads, seconds, False, work)
    print(
        f"(a) offered {s.rate:.0f} msg/s for {seconds:g} s: recorded {res.recorded}/{res.published} "
        f"(lost {res.lost}), {res.rate:.0f} msg/s, {res.mbps:.2f} MB/s; recorder CPU {res.cpu_percent:.0f}%, "
        f"peak RSS {res.peak_rss_mb:.0f} MB",
        flush=True,
    )

    burst, burst_bag = run_recorder(s, payloads, burst_seconds, True, work)
    rb_rate, rb_mbps = writer_alone(burst_bag, work, "rosbags")
    bw_rate, bw_mbps = writer_alone(burst_bag, work, "ours")
    ratio = burst.rate / rb_rate
    verdict = "met" if ratio >= GOAL else "missed"
    bound = (
        "; publisher-bound: the recorder took every message sent, its ceiling is higher"
        if burst.lost == 0
        else ""
    )
    print(
        f"(b) flat out for {burst_seconds:g} s: recorder {burst.rate:.0f} msg/s, {burst.mbps:.2f} MB/s "
        f"(recorded {burst.recorded}/{burst.published} sent, lost {burst.lost}; "
        f"CPU {burst.cpu_percent:.0f}%, peak RSS {burst.peak_rss_mb:.0f} MB){bound}"
    )
    print(f"    rosbags Writer alone, the same messages: {rb_rate:.0f} msg/s, {rb_mbps:.2f} MB/s")
    print(f"    BagWriter alone (for information):       {bw_rate:.0f} msg/s, {bw_mbps:.2f} MB/s")
    print(f"    ratio recorder / rosbags Writer alone: {ratio:.2f} -> goal >= {GOAL} {verdict}", flush=True)
    minimal, _ = run_recorder(s, payloads, burst_seconds, True, work, baseline="write")
    print(
        f"(c) flat out, minimal rclpy recorder (raw subscription -> rosbags Writer): "
        f"{minimal.rate:.0f} msg/s, CPU {minimal.cpu_percent:.0f}%\n"
        f"    ratio minimal / rosbags Writer alone: {minimal.rate / rb_rate:.2f} (what receiving through "
        f"rclpy leaves); recorder / minimal: {burst.rate / minimal.rate:.2f}",
        flush=True,
    )
    take, _ = run_recorder(s, payloads, burst_seconds, True, work, baseline="take-only")
    sender = max(burst.sent_rate, minimal.sent_rate, take.sent_rate)
    ceiling = min(take.rate, sender) / rb_rate
    print(
        f"(d) ceilings here, flat out: the rclpy publisher sends at most {sender:.0f} msg/s "
        f"({sender / rb_rate:.2f} of the Writer alone); taking the raw messages and writing nothing "
        f"receives {take.rate:.0f} msg/s ({take.rate / rb_rate:.2f}, CPU {take.cpu_percent:.0f}%).\n"
        f"    No rclpy recorder can exceed {ceiling:.2f} of the Writer alone on this machine; "
        f"the recorder reaches {burst.rate / min(take.rate, sender):.2f} of that ceiling.",
        flush=True,
    )
    return (
        s.name,
        f"{res.lost}",
        f"{res.cpu_percent:.0f}%",
        f"{res.peak_rss_mb:.0f} MB",
        f"{burst.rate:.0f}",
        f"{burst.mbps:.1f}",
        f"{rb_rate:.0f}",
        f"{ratio:.2f} {verdict}",
        f"{burst.rate / minimal.rate:.2f}",
        f"{ceiling:.2f}",
        f"{burst.rate / min(take.rate, sender):.2f}",
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, help="offered-rate run, seconds (default 10; --quick 4)")
    ap.add_argument("--burst-seconds", type=float, help="flat-out run, seconds (default 5; --quick 2)")
    ap.add_argument("--quick", action="store_true", help="shorter runs (both streams in about a minute)")
    ap.add_argument("--frame", type=int, default=10, help="samples per 64-channel frame (default 10)")
    ap.add_argument("--only", choices=("frames", "strings"), help="run one stream only")
    args = ap.parse_args()
    seconds = args.seconds or (4.0 if args.quick else 10.0)
    burst_seconds = args.burst_seconds or (2.0 if args.quick else 5.0)
    if seconds <= 0 or burst_seconds <= 0 or args.frame < 1:
        ap.error("--seconds, --burst-seconds and --frame must be positive")
    streams = [
        Stream("frames", "std_msgs/msg/Float64MultiArray", 1000.0 / args.frame),
        Stream("strings", "std_msgs/msg/String", 10_000.0),
    ]
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_recorder_") as tmp:
        for s in streams:
            if not args.only or s.name == args.only:
                rows.append(bench_stream(s, args.frame, seconds, burst_seconds, Path(tmp)))
    head = (
        "stream",
        "(a) lost",
        "CPU",
        "peak RSS",
        "(b) msg/s",
        "MB/s",
        "rosbags msg/s",
        f"ratio, goal >= {GOAL}",
        "recorder/minimal",
        "ceiling ratio",
        "recorder/ceiling",
    )
    widths = [max(len(r[i]) for r in (head, *rows)) for i in range(len(head))]
    print("\nsummary")
    for r in (head, *rows):
        print("  " + "  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)))
    return 0


if __name__ == "__main__":
    threading.current_thread().name = "bench"
    sys.exit(main())
