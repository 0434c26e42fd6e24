"""Benchmark physio_receiver against a minimal LSL -> ROS 2 relay, side by side in one run.

Latency: a pylsl outlet pushes a 130 Hz ECG-like stream (counter channel) in real
time; each sample is stamped with local_clock() when pushed, and the ROS 2
subscriber (this process) measures local_clock() at arrival minus the stamp of
the newest sample of each frame. Frames of 1 sample and of 73 samples (a Polar
H10 ECG notification).

Throughput: 64 channels x 1000 Hz for --seconds (default 60) in real time, then
the same amount of data pushed as fast as possible; every sample is checked by
its counter (no loss, no duplicate), and the receiver's sustained rate is
reported as a ratio of the minimal relay's. CPU% and peak RSS of the forwarding
process come from /proc.

Run:  source scripts/env.sh && python bench/bench_receiver.py
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import psutil
import pylsl

HERE = Path(__file__).resolve()


# -- the minimal relay (runs as a subprocess: pylsl inlet -> rclpy publisher) -------------------


def relay_main(name: str, topic: str, frame: int) -> None:
    import rclpy
    from std_msgs.msg import Float64MultiArray

    from hri_physio_bridge.frames import Frame
    from hri_physio_bridge.qos import frame_qos
    from hri_physio_bridge.ros_frames import frame_to_msg

    rclpy.init()
    node = rclpy.create_node("minimal_relay")
    pub = node.create_publisher(Float64MultiArray, topic, frame_qos())
    inlet = pylsl.StreamInlet(pylsl.resolve_byprop("name", name, 1, 30)[0], max_buflen=360)
    inlet.open_stream(10)
    print("relay connected", flush=True)
    pending_t: list[np.ndarray] = []
    pending_v: list[np.ndarray] = []
    have = 0
    try:
        while True:
            data, stamps = inlet.pull_chunk(timeout=0.2, max_samples=4096, min_samples=1, as_numpy=True)
            if stamps is None or len(stamps) == 0:
                continue
            pending_t.append(np.asarray(stamps))
            pending_v.append(np.asarray(data, dtype=np.float64))
            have += len(stamps)
            if have >= frame:
                t = np.concatenate(pending_t)
                v = np.concatenate(pending_v)
                cut = (have // frame) * frame
                for i in range(0, cut, frame):
                    pub.publish(frame_to_msg(Frame(t[i : i + frame], v[i : i + frame])))
                pending_t, pending_v, have = [t[cut:]], [v[cut:]], have - cut
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


# -- measurement side --------------------------------------------------------------------------


@dataclass
class Collected:
    latencies: list[float] = field(default_factory=list)
    counters: list[np.ndarray] = field(default_factory=list)
    samples: int = 0
    last_arrival: float = 0.0


class Subscriber:
    def __init__(self, topic: str) -> None:
        import rclpy
        from std_msgs.msg import Float64MultiArray

        from hri_physio_bridge.qos import frame_qos
        from hri_physio_bridge.ros_frames import msg_to_frame
        from hri_physio_bridge.ros_tools import ExecutorThread

        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node(f"bench_sub_{uuid.uuid4().hex[:6]}", context=self.context)
        self.data = Collected()
        self.topic = topic

        def on_msg(msg: Float64MultiArray) -> None:
            now = pylsl.local_clock()
            f = msg_to_frame(msg)
            self.data.latencies.append(now - f.timestamps[-1])
            self.data.counters.append(f.values[:, 0].copy())
            self.data.samples += f.num_samples
            self.data.last_arrival = now

        self.node.create_subscription(Float64MultiArray, topic, on_msg, frame_qos())
        self._spinner = ExecutorThread(self.node, context=self.context)

    def close(self) -> None:
        self._spinner.close()
        self.node.destroy_node()
        import rclpy

        rclpy.shutdown(context=self.context)


def start_forwarder(kind: str, name: str, topic: str, frame: int, channels: int,
                    rate: float) -> subprocess.Popen:
    env = dict(os.environ)
    if kind == "receiver":
        cmd = [
            str(Path(sys.prefix) / "bin" / "physio_receiver"), "--input", f"lsl:{name}",
            "--output", f"ros:{topic}", "--num-channels", str(channels), "--output-frame", str(frame),
            "--sampling-rate", f"{rate:g}",  # the stream's declared rate: another one is refused
            "--input-frame", "4096", "--buffer-length", "200000", "--wait-for-consumers", "30",
            "--status-period", "3600",
        ]
    else:
        cmd = [sys.executable, str(HERE), "relay", "--name", name, "--topic", topic, "--frame", str(frame)]
    return subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def proc_usage(proc: psutil.Process, wall: float, cpu0: float) -> tuple[float, float]:
    """CPU% over ``wall`` seconds (since cpu0) and peak RSS in MiB (VmHWM)."""
    t = proc.cpu_times()
    cpu = (t.user + t.system - cpu0) / wall * 100.0
    peak = 0.0
    with open(f"/proc/{proc.pid}/status") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                peak = int(line.split()[1]) / 1024.0
    return cpu, peak


def wait_for(pred: Callable[[], bool], timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while not pred():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.02)
    return True


@dataclass
class RunResult:
    latencies: np.ndarray
    samples: int
    lost: int
    duplicated: int
    cpu: float
    peak_rss: float
    rate: float = 0.0


def run(kind: str, channels: int, rate: float, frame: int, chunk: int, seconds: float,
        burst: bool = False) -> RunResult:
    name = f"bench/{uuid.uuid4().hex[:8]}"
    topic = f"/bench/{kind}_{uuid.uuid4().hex[:6]}"
    outlet = pylsl.StreamOutlet(pylsl.StreamInfo(name, "ECG", channels, rate, pylsl.cf_double64, name),
                                chunk_size=0, max_buffered=600)
    sub = Subscriber(topic)
    proc = start_forwarder(kind, name, topic, frame, channels, rate)
    ps = psutil.Process(proc.pid)
    try:
        if not wait_for(lambda: outlet.have_consumers() and sub.node.count_publishers(topic) > 0, 60):
            raise RuntimeError(f"{kind} did not connect")
        # The relay has no wait-for-consumers option: give discovery time to match both ways.
        time.sleep(1.0)
        n = int(rate * seconds)
        n -= n % frame
        base = np.zeros((chunk, channels))
        t_start = time.monotonic()
        c = ps.cpu_times()
        cpu0 = c.user + c.system
        for i in range(0, n, chunk):
            k = min(chunk, n - i)
            block = base[:k].copy()
            block[:, 0] = np.arange(i, i + k)
            now = pylsl.local_clock()
            stamps = now - (k - 1 - np.arange(k)) / rate
            outlet.push_chunk(block, timestamp=stamps)
            if not burst:
                due = t_start + (i + k) / rate
                delay = due - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
        push_end = time.monotonic()
        wait_for(lambda: sub.data.samples >= n, 120 if burst else 30)
        done = time.monotonic()
        cpu, peak = proc_usage(ps, done - t_start, cpu0)
        counters = np.concatenate(sub.data.counters) if sub.data.counters else np.array([])
        uniq = np.unique(counters)
        lost = n - len(uniq)
        dup = len(counters) - len(uniq)
        elapsed = max(done - t_start, push_end - t_start)
        return RunResult(np.array(sub.data.latencies), sub.data.samples, lost, dup, cpu, peak, n / elapsed)
    finally:
        proc.terminate()
        try:
            proc.wait(15)
        except subprocess.TimeoutExpired:
            proc.kill()
        sub.close()


BURST_REPEATS = 5


def ms(x: float) -> str:
    return f"{x * 1e3:7.2f} ms"


def latency_section(seconds: float) -> None:
    print(f"\n== Latency: 130 Hz, 2 channels, {seconds:g} s per run, real time ==")
    print(f"{'frame':>6} {'impl':>9} {'p50':>10} {'p99':>10} {'frames':>7} {'lost':>5} {'dup':>4}")
    for frame in (1, 73):
        res = {}
        for kind in ("relay", "receiver"):
            r = run(kind, 2, 130.0, frame, 1 if frame == 1 else 73, seconds)
            res[kind] = r
            print(f"{frame:>6} {kind:>9} {ms(np.percentile(r.latencies, 50))} "
                  f"{ms(np.percentile(r.latencies, 99))} {len(r.latencies):>7} {r.lost:>5} {r.duplicated:>4}")
        d50 = np.percentile(res["receiver"].latencies, 50) - np.percentile(res["relay"].latencies, 50)
        d99 = np.percentile(res["receiver"].latencies, 99) - np.percentile(res["relay"].latencies, 99)
        ok = d50 <= 0.002 and d99 <= 0.010
        print(f"{frame:>6} {'added':>9} {ms(d50)} {ms(d99)}   goal <= 2 ms p50, <= 10 ms p99: "
              f"{'MET' if ok else 'NOT MET'}")


def throughput_section(seconds: float) -> None:
    print(f"\n== Throughput: 64 channels x 1000 Hz, {seconds:g} s of data, frames of 100 ==")
    print(f"{'mode':>9} {'impl':>9} {'samples':>8} {'lost':>5} {'dup':>4} {'rate/s':>10} {'CPU%':>6} "
          f"{'peakRSS':>8}")
    for burst in (False, True):
        mode = "burst" if burst else "realtime"
        rates: dict[str, list[float]] = {"relay": [], "receiver": []}
        lost = dup = 0
        # A burst shares 2 cores between the pusher, the forwarder and the subscriber, so one
        # run is noisy: alternate the two BURST_REPEATS times and compare the medians.
        for _ in range(BURST_REPEATS if burst else 1):
            for kind in ("relay", "receiver"):
                r = run(kind, 64, 1000.0, 100, 10 if not burst else 1000, seconds, burst=burst)
                rates[kind].append(r.rate)
                if kind == "receiver":
                    lost, dup = lost + r.lost, dup + r.duplicated
                print(f"{mode:>9} {kind:>9} {r.samples:>8} {r.lost:>5} {r.duplicated:>4} {r.rate:>10.0f} "
                      f"{r.cpu:>6.1f} {r.peak_rss:>6.1f}MB")
        ratio = float(np.median(rates["receiver"]) / np.median(rates["relay"]))
        runs = f"median of {len(rates['relay'])} runs each" if burst else "one run each"
        print(f"{mode:>9} receiver/relay sustained-rate ratio: {ratio:.3f} ({runs}; goal >= 0.9: "
              f"{'MET' if ratio >= 0.9 else 'NOT MET'}); receiver lost {lost}, duplicated {dup}")


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    sub = parser.add_subparsers(dest="mode")
    relay = sub.add_parser("relay", help="(internal) run the minimal relay")
    relay.add_argument("--name", required=True)
    relay.add_argument("--topic", required=True)
    relay.add_argument("--frame", type=int, default=1)
    parser.add_argument("--latency-seconds", type=float, default=15.0)
    parser.add_argument("--seconds", type=float, default=60.0, help="throughput duration (default 60)")
    parser.add_argument("--skip-latency", action="store_true")
    parser.add_argument("--skip-throughput", action="store_true")
    args = parser.parse_args()
    if args.mode == "relay":
        relay_main(args.name, args.topic, args.frame)
        return
    print(f"machine: {os.cpu_count()} cores, python {sys.version.split()[0]}, "
          f"ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', '0')}")
    if not args.skip_latency:
        latency_section(args.latency_seconds)
    if not args.skip_throughput:
        throughput_section(args.seconds)


if __name__ == "__main__":
    main()
