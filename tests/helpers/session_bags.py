"""Session bags in tests: write them with the project's bag writer (no rclpy), read them back with
independent readers (rosbags' AnyReader, the mcap stream reader), and check a recorded session's
strap samples against the strap's grid (no sample lost, none twice)."""

from __future__ import annotations

import json
import math
import shutil
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.typesys import Stores, get_typestore

from helpers import DATA
from hri_physio_bridge import topics
from hri_physio_bridge.bag.msgdefs import installed_type_hash, message_definition
from hri_physio_bridge.bag.writer import BagWriter

TS = get_typestore(Stores.LATEST)
DATA = DATA / "report"
#: The real session bag shipped for these tests (tests/data/report/README.md says how it was made).
REAL_BAG = DATA / "session_2026_11_23-18_53_14"
_NEVER = {"sec": 9223372036, "nsec": 854775807}
QOS = [{"history": "unknown", "depth": 0, "reliability": "reliable", "durability": "volatile",
        "deadline": _NEVER, "lifespan": _NEVER, "liveliness": "automatic",
        "liveliness_lease_duration": _NEVER, "avoid_ros_namespace_conventions": False}]


def string_msg(text: str) -> Any:
    return TS.types["std_msgs/msg/String"](data=text)


def frame_msg(timestamps: np.ndarray, values: np.ndarray, channels: tuple[str, ...]) -> Any:
    """A frame in the project's layout (column 0 = time), built by hand (not with frames.py)."""
    values = np.asarray(values, dtype=np.float64).reshape(len(timestamps), -1)
    table = np.column_stack([np.asarray(timestamps, dtype=np.float64), values])
    n, width = table.shape
    dim = TS.types["std_msgs/msg/MultiArrayDimension"]
    layout = TS.types["std_msgs/msg/MultiArrayLayout"](
        dim=[dim(label="samples", size=n, stride=n * width),
             dim(label="channels:" + ",".join(("t", *channels)), size=width, stride=width)],
        data_offset=0)
    return TS.types["std_msgs/msg/Float64MultiArray"](layout=layout, data=table.ravel())


def clock_msg(t: float) -> Any:
    sec = math.floor(t)
    return TS.types["rosgraph_msgs/msg/Clock"](
        clock=TS.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=round((t - sec) * 1e9)))


def log_msg(name: str, text: str) -> Any:
    return TS.types["rcl_interfaces/msg/Log"](
        stamp=TS.types["builtin_interfaces/msg/Time"](sec=0, nanosec=0), level=20, name=name, msg=text,
        file="x.py", function="f", line=1)


@dataclass
class BagBuilder:
    """Messages to write, each with its receive time (ns); :meth:`write` makes the bag."""

    messages: list[tuple[str, str, int, Any]] = field(default_factory=list)  # topic, type, ns, msg

    def add(self, topic: str, type_name: str, log_ns: int, msg: Any) -> None:
        self.messages.append((topic, type_name, int(log_ns), msg))

    def event(self, log_ns: int, data: dict[str, Any], topic: str = topics.COACH_EVENTS) -> None:
        self.add(topic, "std_msgs/msg/String", log_ns, string_msg(json.dumps(data)))

    def write(self, bag_dir: Path) -> Path:
        writer = BagWriter(bag_dir, custom_data={"session_id": "test"})
        for topic, type_name, log_ns, msg in sorted(self.messages, key=lambda m: m[2]):
            if topic not in writer.topics:
                writer.add_topic(topic, type_name, message_definition(type_name),
                                 installed_type_hash(type_name) or "", QOS)
            writer.write(topic, log_ns, TS.serialize_cdr(msg, type_name))
        writer.close()
        return bag_dir


def copy_real_bag(dest: Path) -> Path:
    """A private copy of the shipped session bag (tests may damage it)."""
    return Path(shutil.copytree(REAL_BAG, dest / REAL_BAG.name))


# --- independent readers -------------------------------------------------------------------------
def read_anyreader(bag: Path, wanted: set[str]) -> Iterator[tuple[str, int, Any]]:
    """(topic, receive ns, message) with rosbags' own reader and the bag's own type definitions."""
    from rosbags.highlevel import AnyReader

    with AnyReader([bag], default_typestore=get_typestore(Stores.EMPTY)) as reader:
        conns = [c for c in reader.connections if c.topic in wanted]
        for conn, t, raw in reader.messages(connections=conns):
            yield conn.topic, t, reader.deserialize(raw, conn.msgtype)


def read_stream(mcap_file: Path, wanted: set[str]) -> Iterator[tuple[str, int, Any]]:
    """(topic, receive ns, message) with the mcap library's stream reader, up to the first damaged record
    (a file whose writer was killed has no summary and may end mid-record)."""
    from mcap.records import Channel, Message, Schema
    from mcap.stream_reader import StreamReader

    channels: dict[int, Channel] = {}
    schemas: dict[int, Schema] = {}
    with mcap_file.open("rb") as fh:
        records = StreamReader(fh, skip_magic=False).records
        while True:
            try:
                record = next(records)
            except StopIteration:
                return
            except Exception:  # truncated or damaged from here on
                return
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Message):
                channel = channels[record.channel_id]
                if channel.topic in wanted:
                    type_name = schemas[channel.schema_id].name
                    yield channel.topic, record.log_time, TS.deserialize_cdr(record.data, type_name)


@dataclass
class Recomputed:
    """A session's numbers, recomputed in the tests from independently read messages."""

    events: list[dict[str, Any]]
    clock_ns: np.ndarray
    clock_s: np.ndarray
    hr_ns: np.ndarray
    hr_bpm: np.ndarray
    hr_source_t: np.ndarray

    @classmethod
    def from_messages(cls, messages: Iterator[tuple[str, int, Any]], hr_topic: str) -> Recomputed:
        events, clock_ns, clock_s, hr_ns, hr_bpm, hr_src = [], [], [], [], [], []
        for topic, t, msg in messages:
            if topic == topics.COACH_EVENTS:
                events.append(json.loads(msg.data))
            elif topic == "/clock":
                clock_ns.append(t)
                clock_s.append(msg.clock.sec + msg.clock.nanosec / 1e9)
            elif topic == hr_topic:
                width = msg.layout.dim[1].size
                table = np.asarray(msg.data, dtype=np.float64)[msg.layout.data_offset:].reshape(-1, width)
                hr_ns += [t] * table.shape[0]
                hr_src += list(table[:, 0])
                hr_bpm += list(table[:, 1])
        return cls(events, np.asarray(clock_ns, np.int64), np.asarray(clock_s), np.asarray(hr_ns, np.int64),
                   np.asarray(hr_bpm), np.asarray(hr_src))

    def session_time(self, ns: np.ndarray) -> np.ndarray:
        base = self.clock_ns[0]
        return np.interp((ns - base) / 1e9, (self.clock_ns - base) / 1e9, self.clock_s)

    def of(self, kind: str) -> list[dict[str, Any]]:
        return [e for e in self.events if e.get("event") == kind]

    def phase_windows(self) -> list[tuple[str, float, float]]:
        phases = self.of("phase")
        end = [e["t"] for e in self.events if e.get("event") in ("session_end", "session_stopped")]
        stop = end[0] if end else math.inf
        out = []
        for i, p in enumerate(phases):
            nxt = phases[i + 1]["t"] if i + 1 < len(phases) else math.inf
            out.append((p["kind"], p["t"], min(p["t"] + p["duration"], nxt, stop)))
        return out

    def in_zone(self) -> dict[str, float]:
        zone = self.of("zone")[-1]
        t = self.session_time(self.hr_ns)
        ok = np.isfinite(self.hr_bpm) & (self.hr_bpm >= 30) & (self.hr_bpm <= 230)
        out = {}
        for kind, a, b in self.phase_windows():
            sel = ok & (t >= a) & (t < b)
            if sel.any():
                bpm = self.hr_bpm[sel]
                out[kind] = float(np.mean((bpm >= zone["low"]) & (bpm <= zone["high"])))
        return out


#: The simulated strap's streams as the session records them: receiver -> (topic, rate in Hz).
RECEIVERS = {"hr_receiver": (topics.POLAR_H10_HR, 1.0), "ecg_receiver": (topics.POLAR_H10_ECG, 130.0)}


def session_folder(output: str) -> Path:
    line = next(x for x in output.splitlines() if x.startswith("[session] session folder: "))
    return Path(line.removeprefix("[session] session folder: "))


def failed_nodes_logs(output: str, base: Path = Path(), tail: int = 60) -> str:
    """The launcher's ``output`` and the last ``tail`` lines of the log of every node that did not exit 0.

    A node stuck on its way out is ended with SIGABRT and prints every thread's stack into its log:
    this puts that stack into the failure message, where CI shows it.
    """
    try:
        folder = base / session_folder(output)
        nodes = json.loads((folder / "summary.json").read_text())["nodes"]
    except (StopIteration, OSError, ValueError, KeyError):
        return output
    parts = [output]
    for name, node in nodes.items():
        if node.get("exit_status") not in (0, None):
            log = folder / node["log"]
            lines = log.read_text(errors="replace").splitlines()[-tail:] if log.is_file() else ["(no log)"]
            parts.append(f"--- {name} exited {node['exit_status']}; the end of {log}:\n" + "\n".join(lines))
    return "\n".join(parts)


def bag_messages(bag: Path) -> dict[str, list]:
    """Every message on the session events and the receivers' outputs, in the order recorded."""
    from rosbags.highlevel import AnyReader

    from hri_physio_bridge.frames import decode_layout

    wanted = {topics.SESSION_EVENTS, *(topic for topic, _rate in RECEIVERS.values())}
    out: dict[str, list] = {topic: [] for topic in wanted}
    with AnyReader([bag]) as reader:
        conns = [c for c in reader.connections if c.topic in wanted]
        for conn, _t, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.topic == topics.SESSION_EVENTS:
                out[conn.topic].append(json.loads(msg.data))
            else:
                dims = [(d.label, d.size, d.stride) for d in msg.layout.dim]
                out[conn.topic].append(decode_layout(dims, msg.layout.data_offset, msg.data).timestamps)
    return out


def check_counter(stamps: np.ndarray, rate: float, gaps: list[tuple[float, float]],
                  off_grid: float = 0.01) -> int:
    """The strap's samples are on a grid of 1/rate: each one between the first and the last recorded is
    in the bag, or inside a recorded gap of its receiver; none twice, none out of order. Returns the
    samples the gaps account for.

    ``off_grid``: how far (in sample periods) a step may be from a whole number of periods. Stamps kept
    as the strap made them are within float rounding; a receiver that adds LSL's clock correction
    (``sync=1``, across computers) moves them by each change of its estimate."""
    steps = np.diff(stamps) * rate
    bad = np.flatnonzero(steps <= 0.5)
    assert not len(bad), (f"{len(bad)} duplicated or reordered sample(s) of {len(stamps)}, first at index "
                          f"{bad[0] if len(bad) else -1}: stamps around it "
                          f"{stamps[max(0, bad[0] - 3):bad[0] + 5].tolist() if len(bad) else []}")
    deviation = np.abs(steps - np.round(steps))
    worst = int(np.argmax(deviation))
    assert deviation[worst] < off_grid, (
        f"samples off the strap's grid: {np.count_nonzero(deviation >= off_grid)} step(s) more than "
        f"{off_grid:g} period off a whole number of periods, the worst {deviation[worst]:.3f} period "
        f"({deviation[worst] / rate * 1e6:.0f} us) after the sample stamped {float(stamps[worst])!r}")
    accounted = 0
    for i in np.flatnonzero(steps > 1.5):
        before, after = stamps[i], stamps[i + 1]
        inside = [g for g in gaps if g[0] <= before + 1e-9 and after <= g[1] + 1e-9]
        assert inside, f"{round(steps[i]) - 1} sample(s) missing between {before} and {after}, outside {gaps}"
        accounted += round(steps[i]) - 1
    assert len(stamps) + accounted == round((stamps[-1] - stamps[0]) * rate) + 1
    return accounted
