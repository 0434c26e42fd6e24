"""No command lost, no remote stop (issue 16), with the console scripts as a researcher runs them.

* qt_controller: every line of a 10 000-line burst on /QtController/input gets exactly one
  reply on /QtController/output, in order (the input used to keep 50: 51 of 1000 answered).
* mock_qt_robot: a burst on one of the robot's command topics reaches the mock whole.
* ``exit`` published on the command topic is refused unless ``allow_remote_exit`` is set.
"""

from __future__ import annotations

import signal

import pytest

from helpers import NodeProcess, publish_burst, wait_until

pytestmark = pytest.mark.ros

BURST = 10_000


def publish_all(probe, lines: list[str], publisher=None) -> None:
    """Publish every line at once, as fast as the reliable KEEP_ALL publisher takes them."""
    from std_msgs.msg import String

    publish_burst(publisher or probe.input, (String(data=line) for line in lines))


def test_every_line_of_a_10000_line_burst_gets_one_reply_in_order(wall_probe) -> None:
    p = wall_probe
    # One line in 100 reaches the robot (a volume service call to the mock); the others are out of
    # range and answered by the controller itself: every line is identified by its N.
    lines = [f"set volume {i % 101}" if i % 100 == 0 else f"set volume {101 + i}" for i in range(BURST)]
    reaching_robot = set(lines[::100])
    with NodeProcess("mock_qt_robot") as mock, NodeProcess("qt_controller") as ctl:
        p.wait_answering(60, "qt_controller to answer")
        wait_until(lambda: p.events_sub.get_publisher_count() > 0, 60, "discovery of mock_qt_robot")
        # Volume 1 is not among the burst's volumes: a late event of this warm-up is told apart. Its
        # event arriving proves the mock's event publisher has matched the probe: an event published
        # before that match is not delivered (volatile), which once lost the burst's first event.
        wait_until(lambda: p.send("set volume 1")["ok"] and event_follows(p, "volume", volume=1), 60,
                   lambda: f"the mock's volume service and events:\n{mock.output}")
        with p.lock:
            before = len(p.replies)
        publish_all(p, lines)
        # The two waits together stay inside the test's timeout, so a failure says what is missing.
        wait_until(lambda: len(p.replies) >= before + BURST, 150,
                   lambda: f"{BURST} replies, got {len(p.replies) - before}:\n{ctl.output[-2000:]}")
        with p.lock:
            replies = p.replies[before:]
        assert len(replies) == BURST  # exactly one reply per line
        assert [r["command"] for r in replies] == lines  # in order
        failed = [r for r in replies if r["command"] in reaching_robot and not r["ok"]]
        assert not failed, f"{len(failed)} volume calls failed, e.g. {failed[:3]}:\n{mock.output[-3000:]}"
        expected = [i % 101 for i in range(0, BURST, 100)]
        wait_until(lambda: len(burst_volumes(p)) >= len(expected), 60,
                   lambda: f"volume events: {missing_volumes(p, expected)}:\n{mock.output[-3000:]}")
        assert ctl.proc.poll() is None and mock.proc.poll() is None
    assert [r["ok"] for r in replies] == [i % 100 == 0 for i in range(BURST)]
    assert all("out of range" in r["message"] for r in replies if not r["ok"])
    assert burst_volumes(p) == expected


def event_follows(probe, kind: str, timeout: float = 2.0, **match) -> bool:
    """True once an event ``kind`` with ``match`` has reached the probe within ``timeout`` s."""
    try:
        wait_until(lambda: probe.events_of(kind, **match), timeout, f"{kind} {match}")
    except AssertionError:
        return False
    return True


def burst_volumes(probe) -> list[int]:
    return [e["volume"] for e in probe.events_of("volume") if e["volume"] != 1]


def missing_volumes(probe, expected: list[int]) -> str:
    got = burst_volumes(probe)
    missing = [v for v in expected if v not in got]
    return f"{len(got)} of {len(expected)} arrived, missing {missing[:20]}"


def test_a_burst_on_a_robot_topic_reaches_the_mock_whole(wall_probe) -> None:
    from std_msgs.msg import String

    from hri_physio_bridge import topics
    from hri_physio_bridge.qos import command_qos

    p = wall_probe
    emotion = p.node.create_publisher(String, topics.QT_EMOTION, command_qos())
    names = [f"no_such_face_{i}" for i in range(1000)]  # each refused by name: one event per message
    with NodeProcess("mock_qt_robot") as mock:
        wait_until(lambda: emotion.get_subscription_count() > 0 and p.events_sub.get_publisher_count() > 0,
                   60, lambda: f"discovery of mock_qt_robot:\n{mock.output}")
        # The warm-up's refusal arriving proves the mock's events reach the probe (see above).
        warm_up = String(data="no_such_face_warm_up")
        wait_until(lambda: emotion.publish(warm_up) or event_follows(p, "emotion_refused", name=warm_up.data),
                   60, lambda: f"the mock's refusal of {warm_up.data}:\n{mock.output}")
        publish_all(p, names, emotion)
        wait_until(lambda: len(refused(p)) >= len(names), 120,
                   lambda: f"{len(names)} refusals, got {len(refused(p))}")
        assert mock.stop(signal.SIGINT) == 0, mock.output
    assert refused(p) == names


def refused(probe) -> list[str]:
    return [e["name"] for e in probe.events_of("emotion_refused") if e["name"] != "no_such_face_warm_up"]


def test_remote_exit_is_refused_unless_allowed(wall_probe) -> None:
    p = wall_probe
    with NodeProcess("qt_controller", "--require-listeners", "false") as ctl:
        p.wait_answering(60, "qt_controller to answer")
        refused = p.send("exit")
        assert not refused["ok"] and refused["data"]["error"] == "remote_exit_disabled", refused
        assert "allow_remote_exit" in refused["message"]
        assert p.send("get emotion")["ok"]  # still answering
        assert ctl.proc.poll() is None
        assert ctl.stop(signal.SIGTERM) == 0, ctl.output
    wait_until(lambda: not p.connected(), 30, "the first controller to leave the graph")
    with NodeProcess("qt_controller", "--ros-args", "-p", "allow_remote_exit:=true") as ctl:
        p.wait_answering(60, "the second qt_controller to answer")
        allowed = p.send("exit")
        assert allowed["ok"], allowed
        assert ctl.wait(30) == 0, ctl.output
