"""Playback scheduling on a fake clock: timing, rate, as-fast-as-possible, loop, /clock steps."""

from __future__ import annotations

import itertools
import threading

import pytest

from hri_physio_bridge.bag.errors import BagError
from hri_physio_bridge.bag.playback import NS, PlaybackOptions, Player
from hri_physio_bridge.bag.reader import BagMessage
from hri_physio_bridge.bag.recorded_qos import adapted_qos, policy_values, qos_to_dict
from hri_physio_bridge.bag.topic_selection import TopicSelector, bag_name, is_hidden, parse_remaps

T0 = 1_700_000_000 * NS


class FakeTime:
    """now()/sleep() pair: sleeping advances time; records every sleep."""

    def __init__(self) -> None:
        self.t = 1000.0
        self.sleeps: list[float] = []

    def now(self) -> float:
        return self.t

    def sleep(self, s: float) -> None:
        self.sleeps.append(s)
        self.t += s


def _msgs(offsets_s: list[float], topic: str = "/a") -> list[BagMessage]:
    return [
        BagMessage(topic, "std_msgs/msg/String", T0 + round(o * NS), str(i).encode())
        for i, o in enumerate(offsets_s)
    ]


def _run(
    msgs: list[BagMessage], **opts
) -> tuple[list[tuple[float, BagMessage]], list[tuple[float, int]], Player]:
    clock = FakeTime()
    sent: list[tuple[float, BagMessage]] = []
    ticks: list[tuple[float, int]] = []
    player = Player(
        lambda: iter(msgs),
        lambda m: sent.append((clock.t, m)),
        PlaybackOptions(**opts),
        publish_clock=lambda t: ticks.append((clock.t, t)),
        now=clock.now,
        sleep=clock.sleep,
    )
    player.run()
    return sent, ticks, player


def test_original_timing() -> None:
    offsets = [0.0, 0.5, 0.5, 1.25, 3.0]
    sent, _, player = _run(_msgs(offsets))
    assert [m.data for _, m in sent] == [b"0", b"1", b"2", b"3", b"4"]
    assert [t - 1000.0 for t, _ in sent] == pytest.approx(offsets, abs=1e-9)
    assert player.stats.messages == 5 and player.stats.passes == 1


def test_rate_scales_time() -> None:
    sent, _, _ = _run(_msgs([0.0, 1.0, 2.0, 10.0]), rate=20.0)
    assert [t - 1000.0 for t, _ in sent] == pytest.approx([0.0, 0.05, 0.1, 0.5], abs=1e-9)


def test_rate_zero_never_sleeps_and_keeps_order() -> None:
    msgs = _msgs([0.0, 5.0, 5.0, 100.0, 3600.0])
    clock = FakeTime()
    sent: list[BagMessage] = []
    Player(lambda: iter(msgs), sent.append, PlaybackOptions(rate=0), now=clock.now, sleep=clock.sleep).run()
    assert sent == msgs and clock.sleeps == []


def test_late_messages_go_out_at_once_in_order() -> None:
    """A slow publish (0.3 s each) stretches playback but never reorders or drops."""
    clock = FakeTime()
    sent: list[BagMessage] = []

    def slow(m: BagMessage) -> None:
        sent.append(m)
        clock.t += 0.3

    msgs = _msgs([0.0, 0.1, 0.2, 0.3])
    p = Player(lambda: iter(msgs), slow, PlaybackOptions(), now=clock.now, sleep=clock.sleep)
    stats = p.run()
    assert sent == msgs and stats.max_lateness == pytest.approx(0.6, abs=1e-9)


def test_loop_replays_until_stopped_and_clock_never_goes_back() -> None:
    msgs = _msgs([0.0, 0.02, 0.05])
    clock = FakeTime()
    stop = threading.Event()
    sent: list[BagMessage] = []
    ticks: list[int] = []

    def publish(m: BagMessage) -> None:
        sent.append(m)
        if len(sent) == 3 * 4:
            stop.set()

    p = Player(
        lambda: iter(msgs),
        publish,
        PlaybackOptions(loop=True, clock_step_ns=10_000_000),
        publish_clock=ticks.append,
        now=clock.now,
        sleep=clock.sleep,
        stop=stop,
    )
    stats = p.run()
    assert len(sent) == 12 and stats.passes == 3 and stats.stopped
    steps = [b - a for a, b in itertools.pairwise(ticks)]
    assert steps and all(s == 10_000_000 for s in steps)  # monotonic, exactly one step each


def test_clock_steps_bounded_and_cover_each_message() -> None:
    step = 10_000_000
    msgs = _msgs([0.0, 0.003, 0.5, 0.5, 2.0])
    events: list[tuple[str, int]] = []
    Player(
        lambda: iter(msgs),
        lambda m: events.append(("msg", m.log_time_ns)),
        PlaybackOptions(rate=0, clock_step_ns=step),
        publish_clock=lambda t: events.append(("clock", t)),
    ).run()
    times = [t for kind, t in events if kind == "clock"]
    assert times[0] == T0 and all(b - a == step for a, b in itertools.pairwise(times))
    assert times[-1] == T0 + 2 * NS  # reaches the last message's time
    clock = None
    for kind, t in events:  # when a message goes out, sim time is within one step before it
        if kind == "clock":
            clock = t
        else:
            assert clock is not None and t - step < clock <= t


def test_clock_at_rate_follows_wall_time() -> None:
    sent, ticks, _ = _run(_msgs([0.0, 1.0]), rate=2.0, clock_step_ns=250_000_000)
    assert [w - 1000.0 for w, _ in ticks] == pytest.approx([0.0, 0.125, 0.25, 0.375, 0.5])
    assert [(t - T0) / NS for _, t in ticks] == pytest.approx([0.0, 0.25, 0.5, 0.75, 1.0])
    assert sent[-1][0] - 1000.0 == pytest.approx(0.5)


def test_stop_interrupts_a_long_wait() -> None:
    clock = FakeTime()
    stop = threading.Event()

    def sleep(s: float) -> None:
        clock.sleep(s)
        if clock.t > 1002.0:
            stop.set()

    sent: list[BagMessage] = []
    stats = Player(
        lambda: iter(_msgs([0.0, 3600.0])),
        sent.append,
        PlaybackOptions(),
        now=clock.now,
        sleep=sleep,
        stop=stop,
    ).run()
    assert len(sent) == 1 and stats.stopped and max(clock.sleeps) <= 0.05 + 1e-12


def test_options_validated() -> None:
    with pytest.raises(ValueError, match="rate"):
        PlaybackOptions(rate=-1)
    with pytest.raises(ValueError, match="clock step"):
        PlaybackOptions(clock_step_ns=0)


def test_topic_selection_and_remaps() -> None:
    assert TopicSelector().selects("/a") and not TopicSelector().selects("/_hidden/x")
    assert is_hidden("/ns/_action/status") and not is_hidden("/a_b")
    sel = TopicSelector(["/a"], regex=r"/physio/.*", exclude=r".*/status")
    assert sel.selects("/a") and sel.selects("/physio/h10/ecg") and not sel.selects("/physio/x/status")
    assert not sel.selects("/b")
    with pytest.raises(BagError, match="regular expression"):
        TopicSelector(regex="(")
    with pytest.raises(BagError, match="absolute"):
        TopicSelector(["a"])
    assert parse_remaps(["/a:=/b"]) == {"/a": "/b"}
    with pytest.raises(BagError, match="/from:=/to"):
        parse_remaps(["/a=/b"])
    from datetime import datetime

    assert bag_name("P012", datetime(2025, 1, 2, 3, 4, 5)) == "P012_2025_01_02-03_04_05"
    with pytest.raises(BagError, match="session id"):
        bag_name("Jane Doe", datetime(2025, 1, 2))


def test_qos_mapping() -> None:
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    latched = qos_to_dict(QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    assert latched["durability"] == "transient_local" and latched["reliability"] == "reliable"
    assert latched["deadline"] == {"sec": 0, "nsec": 0}
    best = qos_to_dict(QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT))
    assert policy_values(best)["reliability"] == int(ReliabilityPolicy.BEST_EFFORT)
    assert adapted_qos([latched, latched], 100) == {
        "history": "keep_last",
        "depth": 100,
        "reliability": "reliable",
        "durability": "transient_local",
    }
    mixed = adapted_qos([latched, best], 100)
    assert mixed["reliability"] == "best_effort" and mixed["durability"] == "volatile"
    assert adapted_qos([], 10)["reliability"] == "reliable"
