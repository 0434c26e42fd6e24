"""LSL sample -> station coach input latency: across a lab of network namespaces, beside one host.

A pylsl outlet (the strap's side) pushes a 130 Hz stream in real time, each sample stamped with
local_clock() when pushed; physio_receiver turns it into the coach's input topic on ROS 2; a
subscriber where the coach runs measures local_clock() at arrival minus the stamp of the newest
sample of each frame (one sample per frame, as the HR receiver sends). Namespaces share the
kernel's monotonic clock, so stamps from the sensor namespace compare with arrivals in the station's.

* one host: outlet, receiver and subscriber on this machine (LOCALHOST discovery, config/lsl_api.cfg);
* lab: the outlet in a "sensor" namespace, receiver and subscriber in a "station" namespace, joined
  by veth pairs on a bridge, with the lab's generated ROS discovery and lsl_api.cfg (root only; the
  namespaces are removed at the end). DDS on UDP only in both runs, as between two computers.

Prints p50/p99 side by side; asserts nothing (the machine may be shared).

Run:  source scripts/env.sh && sudo -E python bench/bench_lab_latency.py [--seconds 30]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

HERE = Path(__file__).resolve()
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT / "tests"))  # helpers.netns: the namespace lab of the tests

RATE = 130.0


def push_main(name: str, seconds: float) -> None:
    import pylsl

    outlet = pylsl.StreamOutlet(pylsl.StreamInfo(name, "ECG", 1, RATE, "double64", f"bench-{name}"))
    start = time.monotonic()
    n = 0
    while time.monotonic() - start < seconds:
        due = start + n / RATE
        delay = due - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        outlet.push_sample([float(n)], pylsl.local_clock())
        n += 1


def listen_main(topic: str, seconds: float) -> None:
    import pylsl
    import rclpy
    from std_msgs.msg import Float64MultiArray

    from hri_physio_bridge.qos import frame_qos
    from hri_physio_bridge.ros_frames import msg_to_frame

    rclpy.init()
    node = rclpy.create_node(f"bench_coach_input_{uuid.uuid4().hex[:6]}")
    latencies: list[float] = []

    def on_msg(msg: Float64MultiArray) -> None:
        latencies.append(pylsl.local_clock() - float(msg_to_frame(msg).timestamps[-1]))

    node.create_subscription(Float64MultiArray, topic, on_msg, frame_qos())
    deadline = time.monotonic() + seconds + 120
    first = None
    while time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.05)
        if latencies and first is None:
            first = time.monotonic()
        if first is not None and time.monotonic() - first >= seconds:
            break
    print(json.dumps(latencies[int(RATE):]))  # the first second: connections settling


def run(label: str, seconds: float, sensor: list[str], station: list[str], sensor_env: dict[str, str],
        station_env: dict[str, str]) -> list[float]:
    tag = uuid.uuid4().hex[:6]
    name, topic = f"LabBench{tag}/ECG", f"/bench_{tag}/ecg"
    receiver = [str(Path(sys.prefix) / "bin" / "physio_receiver"), "--input", f"lsl:{name}",
                "--output", f"ros:{topic}", "--output-frame", "1", "--sampling-rate", f"{RATE:g}",
                "--wait-for-consumers", "120", "--resolve-timeout", "120", "--status-period", "3600"]
    procs = []
    log_path = Path(tempfile.gettempdir()) / f"bench_lab_latency_{tag}.log"  # the receiver's output
    try:
        listener = subprocess.Popen([*station, sys.executable, str(HERE), "listen", topic, str(seconds)],
                                    env=station_env, stdout=subprocess.PIPE, text=True)
        procs.append(listener)
        with open(log_path, "w") as log:
            procs.append(subprocess.Popen([*station, *receiver], env=station_env, stdout=log,
                                          stderr=subprocess.STDOUT))
        procs.append(subprocess.Popen([*sensor, sys.executable, str(HERE), "push", name, str(seconds + 150)],
                                      env=sensor_env))
        out, _ = listener.communicate(timeout=seconds + 200)
        if not out.strip():
            print(f"{label}: nothing measured; the receiver's output is in {log_path}")
            return []
        log_path.unlink(missing_ok=True)
        return json.loads(out.strip().splitlines()[-1])
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()


def percentiles(values: list[float]) -> str:
    import numpy as np

    if not values:
        return f"{'-':>10} {'-':>10} {0:>7}"
    p50, p99 = np.percentile(values, [50, 99]) * 1e3
    return f"{p50:8.2f} ms {p99:8.2f} ms {len(values):>7}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("mode", nargs="?", default="bench", choices=["bench", "push", "listen"])
    parser.add_argument("args", nargs="*")
    parser.add_argument("--seconds", type=float, default=30.0, help="measured seconds per run")
    args = parser.parse_args()
    if args.mode == "push":
        return push_main(args.args[0], float(args.args[1]))
    if args.mode == "listen":
        return listen_main(args.args[0], float(args.args[1]))

    from helpers.netns import NetnsLab, unavailable_reason
    from hri_physio_bringup.isolation import claim_domain
    from hri_physio_bringup.lab import lsl_config, parse_lab, ros_environment

    base = {k: v for k, v in os.environ.items() if k not in ("ROS_DOMAIN_ID", "ROS_STATIC_PEERS")}
    base["FASTDDS_BUILTIN_TRANSPORTS"] = "UDPv4"
    claim = claim_domain(None, {"pid": os.getpid(), "role": "bench_lab_latency"})
    results = {}
    try:
        local = {**base, "ROS_DOMAIN_ID": str(claim.domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
                 "LSLAPICFG": str(ROOT / "config" / "lsl_api.cfg")}
        results["one host"] = run("one host", args.seconds, [], [], local, local)
        reason = unavailable_reason()
        if reason is None:
            with NetnsLab(["sensor", "station"]) as net, tempfile.TemporaryDirectory() as tmp:
                lab = parse_lab({"lab": f"bench-{net.tag}", "ros_domain": claim.domain,
                                 "hosts": {h: net.address(h) for h in ("sensor", "station")},
                                 "roles": {"sensor": "sensor", "robot": "station", "station": "station"}})
                envs = {}
                for role in ("sensor", "station"):
                    cfg = Path(tmp) / f"{role}.cfg"
                    cfg.write_text(lsl_config(lab, role))
                    envs[role] = {**base, **ros_environment(lab, role), "LSLAPICFG": str(cfg)}
                results["lab (namespaces)"] = run("lab", args.seconds, net.command("sensor", []),
                                                  net.command("station", []), envs["sensor"], envs["station"])
        else:
            print(f"lab run skipped: {reason}")
    finally:
        claim.release()
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    print(f"\nLSL sample -> coach input (physio_receiver, 1-sample frames, {RATE:g} Hz, {args.seconds:g} s; "
          f"load average {load})")
    print(f"{'':<18} {'p50':>11} {'p99':>11} {'frames':>7}")
    for label, values in results.items():
        print(f"{label:<18} {percentiles(values)}")


if __name__ == "__main__":
    main()
