"""Frame codec round trips, the streamer factory, dtype names and the CSV streamer."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from std_msgs.msg import Float64MultiArray, MultiArrayDimension, String

from hri_physio_bridge.frames import Frame, FrameFormatError
from hri_physio_bridge.ros_frames import (
    frame_to_msg,
    marker_to_msg,
    msg_to_frame,
    msg_to_marker,
    string_frame_to_msgs,
)
from hri_physio_bridge.streamers import (
    StreamerError,
    StreamMismatchError,
    StreamNotFoundError,
    StreamSpec,
    canonical_dtype,
    create_streamer,
    numpy_dtype,
    split_uri,
)
from hri_physio_bridge.streamers.csv_stream import CsvStreamer, CsvWriter
from hri_physio_bridge.streamers.lsl import LslStreamer, cast_for_output

NUMERIC = ["float64", "float32", "int64", "int32", "int16", "int8"]


def sample_values(dtype: str, n: int, c: int) -> np.ndarray:
    dt = numpy_dtype(dtype)
    if dt.kind == "i":
        info = np.iinfo(dt)
        lo, hi = max(info.min, -(2**53)), min(info.max, 2**53)
        base = np.linspace(lo, hi, n * c)
        return np.rint(base).astype(dt).reshape(n, c)
    return (np.random.default_rng(0).standard_normal((n, c)) * 1e3).astype(dt)


@pytest.mark.parametrize("dtype", NUMERIC)
@pytest.mark.parametrize("n,c", [(1, 1), (73, 1), (5, 3), (0, 2)])
def test_frame_msg_round_trip_every_dtype(dtype: str, n: int, c: int) -> None:
    values = sample_values(dtype, n, c)
    t = 1000.0 + np.arange(n) / 130.0 + 1e-9  # LSL-clock-like, fractional
    frame = Frame(t, values, tuple(f"ch{i}" for i in range(c)))
    msg = frame_to_msg(frame)
    assert [d.label.split(":")[0] for d in msg.layout.dim] == ["samples", "channels"]
    assert msg.layout.dim[1].label == "channels:" + ",".join(["t", *frame.channels])
    back = msg_to_frame(msg)
    np.testing.assert_array_equal(back.timestamps, t)  # bit-exact
    np.testing.assert_array_equal(back.values.astype(numpy_dtype(dtype)), values)
    assert back.channels == frame.channels


def test_msg_without_channel_names_and_with_data_offset() -> None:
    msg = Float64MultiArray()
    msg.layout.dim = [
        MultiArrayDimension(label="samples", size=2, stride=6),
        MultiArrayDimension(label="channels", size=3, stride=3),
    ]
    msg.layout.data_offset = 1
    msg.data = [99.0, 1.0, 10.0, 20.0, 2.0, 11.0, 21.0]
    f = msg_to_frame(msg)
    np.testing.assert_array_equal(f.timestamps, [1.0, 2.0])
    np.testing.assert_array_equal(f.values, [[10, 20], [11, 21]])
    assert f.channels == ("ch1", "ch2")


@pytest.mark.parametrize(
    "dims,data,match",
    [
        ([("x", 1, 2), ("channels", 2, 2)], [0.0, 1.0], "expected 2 dims"),
        ([("samples", 2, 4), ("channels:t,a", 2, 2)], [0.0, 1.0], "data holds 2 values"),
        ([("samples", 1, 2), ("chan:t,a", 2, 2)], [0.0, 1.0], "must start with 'channels'"),
        ([("samples", 1, 2), ("channels:x,a", 2, 2)], [0.0, 1.0], "must list 't'"),
        ([("samples", 1, 0), ("channels", 0, 0)], [], "at least the timestamp"),
    ],
)
def test_malformed_frame_messages_are_named(dims: list, data: list, match: str) -> None:
    msg = Float64MultiArray()
    msg.layout.dim = [MultiArrayDimension(label=lab, size=s, stride=st) for lab, s, st in dims]
    msg.data = data
    with pytest.raises(FrameFormatError, match=match):
        msg_to_frame(msg)


def test_frame_shape_errors() -> None:
    with pytest.raises(FrameFormatError, match="3 samples but 2 timestamps"):
        Frame(np.zeros(2), np.zeros((3, 1)))
    with pytest.raises(FrameFormatError, match="2 channel names"):
        Frame(np.zeros(2), np.zeros((2, 1)), ("a", "b"))
    with pytest.raises(FrameFormatError, match="String markers"):
        frame_to_msg(Frame(np.zeros(1), np.array([["x"]], dtype=object)))


def test_markers_round_trip_and_bad_markers() -> None:
    frame = Frame(np.array([1.5, 2.5]), np.array([["start"], ['say "hi"']], dtype=object), ("marker",))
    msgs = string_frame_to_msgs(frame)
    assert [json.loads(m.data) for m in msgs] == [
        {"t": 1.5, "data": "start"}, {"t": 2.5, "data": 'say "hi"'}
    ]
    assert msg_to_marker(marker_to_msg(3.25, "x")) == (3.25, "x")
    for bad in ["not json", '{"data": "x"}', '{"t": "nan", "data": "x"}', "[1, 2]"]:
        with pytest.raises(FrameFormatError):
            msg_to_marker(String(data=bad))


def test_dtype_names_and_aliases() -> None:
    assert canonical_dtype("double") == "float64"
    assert canonical_dtype("char") == "int8"
    assert canonical_dtype("FLOAT") == "float32"
    assert canonical_dtype("string") == "string"
    assert numpy_dtype("string") == np.dtype(object)
    with pytest.raises(ValueError, match="unknown dtype 'complex'"):
        canonical_dtype("complex")


def test_factory_picks_streamers_and_rejects_bad_uris(tmp_path: Path) -> None:
    assert isinstance(create_streamer("lsl:PolarH10/1234/ECG?type=ECG"), LslStreamer)
    assert isinstance(create_streamer(f"csv:{tmp_path / 'x.csv'}?rate=0"), CsvStreamer)
    assert split_uri("ROS:/physio/x") == ("ros", "/physio/x")
    with pytest.raises(ValueError, match=r"unknown stream scheme 'udp'.*known schemes: csv, lsl, ros"):
        create_streamer("udp:1234")
    with pytest.raises(ValueError, match="has no scheme"):
        create_streamer("PolarH10/1234/ECG")
    with pytest.raises(ValueError, match="empty"):
        create_streamer("lsl:")
    with pytest.raises(ValueError, match="unknown LSL option"):
        create_streamer("lsl:X?colour=red")
    with pytest.raises(ValueError, match="unknown CSV option"):
        create_streamer("csv:x.csv?speed=2")
    with pytest.raises(ValueError, match="rate must be"):
        create_streamer("csv:x.csv?rate=-1")
    with pytest.raises(StreamerError, match="needs a ROS 2 node"):
        create_streamer("ros:/x")


def test_stream_spec_validation() -> None:
    with pytest.raises(ValueError, match="channel_count"):
        StreamSpec("x", channel_count=0)
    with pytest.raises(ValueError, match="nominal_rate"):
        StreamSpec("x", nominal_rate=-1)
    with pytest.raises(ValueError, match="3 channel names given for 2"):
        StreamSpec("x", channel_count=2, channels=("a", "b", "c"))


def test_cast_for_output_refuses_what_it_cannot_hold() -> None:
    np.testing.assert_array_equal(cast_for_output(np.array([1.0, 2.0]), np.dtype(np.int8), "w"), [1, 2])
    with pytest.raises(StreamMismatchError, match="outside"):
        cast_for_output(np.array([300.0]), np.dtype(np.int8), "w")
    with pytest.raises(StreamMismatchError, match="NaN"):
        cast_for_output(np.array([np.nan]), np.dtype(np.int32), "w")
    # int64 stays exact (no detour through float64), and 2**63 as a float does not wrap around.
    big = np.array([2**63 - 1, 2**53 + 1, -(2**63)], dtype=np.int64)
    np.testing.assert_array_equal(cast_for_output(big, np.dtype(np.int64), "w"), big)
    with pytest.raises(StreamMismatchError, match="outside"):
        cast_for_output(np.array([2.0**63]), np.dtype(np.int64), "w")


# -- CSV ------------------------------------------------------------------------


@pytest.mark.parametrize("dtype", [*NUMERIC, "string"])
def test_csv_round_trip_every_dtype(tmp_path: Path, dtype: str) -> None:
    path = tmp_path / "log.csv"
    spec = StreamSpec("x", channel_count=2, dtype=dtype, channels=("a", "b"))
    out = create_streamer(f"csv:{path}")
    out.open_output(spec)
    frames = []
    for i in range(3):
        t = 5000.0 + np.arange(i * 4, i * 4 + 4) / 130.0
        if dtype == "string":
            values = np.array([[f"m{i}{j}", "x,y \"q\""] for j in range(4)], dtype=object)
        else:
            values = sample_values(dtype, 4, 2)
        frame = Frame(t, values, ("a", "b"))
        frames.append(frame)
        out.publish(frame)
    out.close()
    assert path.read_text().splitlines()[0] == "t,a,b"

    inp = create_streamer(f"csv:{path}?rate=0&dtype={dtype}", max_chunk=5)
    got_spec = inp.open_input()
    assert got_spec.channels == ("a", "b") and got_spec.dtype == dtype
    chunks = []
    while (c := inp.receive()) is not None:
        chunks.append(c)
    assert inp.exhausted
    assert [c.num_samples for c in chunks] == [5, 5, 2]
    back = Frame.concat(chunks)
    ref = Frame.concat(frames)
    np.testing.assert_array_equal(back.timestamps, ref.timestamps)
    np.testing.assert_array_equal(back.values, ref.values)


def test_csv_writer_refuses_to_overwrite(tmp_path: Path) -> None:
    path = tmp_path / "log.csv"
    path.write_text("precious\n")
    with pytest.raises(StreamerError, match="refusing to overwrite"):
        CsvWriter(path, ("a",))
    assert path.read_text() == "precious\n"


def test_csv_input_errors_name_the_problem(tmp_path: Path) -> None:
    with pytest.raises(StreamNotFoundError, match="does not exist"):
        create_streamer(f"csv:{tmp_path / 'missing.csv'}").open_input()
    bad_header = tmp_path / "h.csv"
    bad_header.write_text("time,a\n1,2\n")
    with pytest.raises(StreamMismatchError, match="header starting with 't'"):
        create_streamer(f"csv:{bad_header}").open_input()
    ragged = tmp_path / "r.csv"
    ragged.write_text("t,a\n1,2\n2,3,4\n")
    s = create_streamer(f"csv:{ragged}?rate=0")
    s.open_input()
    assert s.receive().num_samples == 1  # the good row first, then the error
    with pytest.raises(StreamMismatchError, match=r"r\.csv:3: expected 2 columns, got 3"):
        s.receive()
    text = tmp_path / "n.csv"
    text.write_text("t,a\n1,abc\n")
    s = create_streamer(f"csv:{text}?rate=0")
    s.open_input()
    with pytest.raises(StreamMismatchError, match="not a number"):
        s.receive()
    wide = tmp_path / "w.csv"
    wide.write_text("t,a,b\n1,2,3\n")
    with pytest.raises(StreamMismatchError, match=r"2 data column.*num_channels is 1"):
        create_streamer(f"csv:{wide}").open_input(StreamSpec("w", channel_count=1))


def _read_all(path: Path, max_chunk: int = 1024) -> tuple[list[float], Exception | None]:
    s = CsvStreamer(f"{path}?rate=0", max_chunk=max_chunk)
    s.open_input()
    got: list[float] = []
    try:
        while (frame := s.receive()) is not None:
            got.extend(frame.timestamps.tolist())
    except StreamMismatchError as exc:
        return got, exc
    return got, None


@pytest.mark.parametrize(
    "body,line,what",
    [
        (b"t,a\n1,abc\n2,3\n3,4\n", 2, "not a number"),  # reported as line 4 (the chunk's end) before
        (b"t,a\n1,1\n\n2,x\n", 4, "not a number"),  # blank lines count as lines
        (b"t,a\n1,1\n2,2,2\n", 3, "expected 2 columns, got 3"),
        (b"t,a\n1,1\n2,\xff\xfe\n3,3\n", 3, "not UTF-8 text"),  # UnicodeDecodeError traceback before
        (b"t,a\r1,1\r2,oops\r", 3, "not a number"),  # lines ended by a carriage return alone
        (b"t,a\r\n1,1\r\n2,oops\r\n", 3, "not a number"),
    ],
)
def test_csv_input_errors_name_the_exact_line_after_the_good_rows(tmp_path: Path, body: bytes, line: int,
                                                                   what: str) -> None:
    path = tmp_path / "in.csv"
    path.write_bytes(body)
    got, error = _read_all(path)
    assert error is not None and str(error).startswith(f"{path}:{line}: {what}"), error
    assert got == [float(i) for i in range(1, line - body.count(b"\n\n") - 1)]  # every row before it


def test_csv_header_that_is_not_utf8_is_named(tmp_path: Path) -> None:
    path = tmp_path / "h.csv"
    path.write_bytes(b"t,\xe9cg\n1,2\n")
    with pytest.raises(StreamMismatchError, match=r"h\.csv:1: not UTF-8 text"):
        CsvStreamer(str(path)).open_input()


def test_csv_utf8_labels_and_strings_read_back(tmp_path: Path) -> None:
    path = tmp_path / "u.csv"
    path.write_text("t,marker\n1,ünïcode\n2,\"a, b\"\n", encoding="utf-8")
    s = CsvStreamer(f"{path}?rate=0&dtype=string")
    s.open_input()
    frame = s.receive()
    assert frame.values[:, 0].tolist() == ["ünïcode", "a, b"]


def test_csv_replay_paces_by_timestamps(tmp_path: Path) -> None:
    path = tmp_path / "p.csv"
    path.write_text("t,a\n" + "".join(f"{10 + i * 0.5},{i}\n" for i in range(5)))
    now = [0.0]
    sleeps: list[float] = []

    def sleep(dt: float) -> None:
        sleeps.append(dt)
        now[0] += dt

    s = CsvStreamer(f"{path}?rate=2", max_chunk=1, monotonic=lambda: now[0], sleep=sleep)
    s.open_input()
    while not s.exhausted:
        s.receive(timeout=1.0)
    # 0.5 s of recording per row at 2x speed = 0.25 s per row, after the first.
    assert sleeps == pytest.approx([0.25] * 4)


def test_csv_replay_waits_for_a_row_at_most_the_timeout_and_never_holds_due_rows(tmp_path: Path) -> None:
    """A 60 s gap in the stamps: the rows before it go out when due, and each call waits at most its
    timeout for the row after it (a stop is never held up by the gap)."""
    path = tmp_path / "p.csv"
    rows = [10.0, 10.5, 11.0, 71.0, 71.5]
    path.write_text("t,a\n" + "".join(f"{t},{i}\n" for i, t in enumerate(rows)))
    now = [0.0]

    def sleep(dt: float) -> None:
        assert dt <= 0.1 + 1e-9
        now[0] += dt

    s = CsvStreamer(f"{path}?rate=1", max_chunk=32, monotonic=lambda: now[0], sleep=sleep)
    s.open_input()
    got: list[tuple[float, float]] = []  # (stamp, when it came out)
    calls = 0
    while not s.exhausted:
        calls += 1
        frame = s.receive(timeout=0.1)
        if frame is not None:
            got += [(t, now[0]) for t in frame.timestamps]
    assert [t for t, _ in got] == rows
    for t, when in got:
        assert when == pytest.approx(t - 10.0, abs=1e-6)  # each row when it is due, not later
    assert calls > 600  # the gap was waited out in calls of 0.1 s


def test_a_fast_paced_csv_comes_in_chunks_of_at_most_the_batch_window(tmp_path: Path) -> None:
    """1 kHz rows at 1x: chunks of about BATCH_WINDOW (50 rows), none held back longer than that."""
    from hri_physio_bridge.streamers.csv_stream import BATCH_WINDOW

    path = tmp_path / "fast.csv"
    path.write_text("t,a\n" + "".join(f"{100 + i / 1000},{i}\n" for i in range(1000)))
    now = [0.0]

    def sleep(dt: float) -> None:
        now[0] += dt

    s = CsvStreamer(f"{path}?rate=1", max_chunk=1024, monotonic=lambda: now[0], sleep=sleep)
    s.open_input()
    sizes, late = [], []
    while not s.exhausted:
        frame = s.receive(timeout=0.1)
        if frame is not None:
            sizes.append(frame.num_samples)
            late += [now[0] - (t - 100.0) for t in frame.timestamps]  # how long after it was due
    assert sum(sizes) == 1000 and len(sizes) <= 1000 / (BATCH_WINDOW * 1000) + 2
    assert max(late) <= BATCH_WINDOW + 1e-6
