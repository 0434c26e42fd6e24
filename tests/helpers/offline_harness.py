"""Offline-test harness: record a live session through real nodes, replay it into fresh ones.

Generic over nodes and topics:

* :meth:`OfflineHarness.record` starts the recorder on some topics, then the nodes of a live
  session (console scripts) one by one, waits until every topic is being recorded and the
  nodes that run to an end have ended, stops the others (SIGINT, exit 0 asserted, upstream
  first), closes the bag. Record both the *inputs* and the *outputs* of the nodes under
  test: the bag is then the reference their fresh instances must reproduce;
* :meth:`OfflineHarness.replay` starts fresh nodes and a recorder on their outputs, plays the
  chosen input topics of a bag into them as fast as possible (order kept, after they have
  subscribed), stops them, and returns the bag of their outputs;
* :meth:`OfflineHarness.decoded` / :meth:`assert_same` compare topics of two bags message by
  message (decoded values: DDS alignment padding may differ byte-wise between runs).

A node's live output can be reproduced only if the bag holds every input message that node
saw, and the node saw every one the bag holds. ROS 2 topics are volatile, and a publisher
that waits for "a" subscriber starts as soon as the first one is matched: when two processes
listen to it (the recorder and the node under test), DDS discovery may match the second one
later, and it misses the first frames (seen on a 2-core machine in 3 of 8 runs: the recorder
or the node under test lost the first 3 to 14 frames of 30). So:

* the upstream node must hold its stream until all of its readers are matched: for
  ``physio_receiver``, ``--wait-for-consumers S --min-consumers N`` (N = the recorder + the
  nodes under test). A reliable publisher delivers every message published after a
  subscription was matched, so each of them receives the whole stream, whatever the
  discovery timing;
* ``NodeSpec.publishes``: after starting that node, the harness waits until the recorder
  records those topics before starting the next node (which may be the data source);
* stopping waits ``stop_gap`` seconds between nodes, so a downstream node has taken the
  frames its upstream node published at shutdown before it is stopped itself.
"""

from __future__ import annotations

import signal
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from helpers import NodeProcess
from hri_physio_bridge.bag.reader import BagReader


@dataclass(frozen=True)
class NodeSpec:
    script: str
    args: tuple[str, ...] = ()
    runs_to_end: bool = False  # wait for it to exit by itself (a simulator with --seconds)
    ready: str | None = None  # text its output shows once it is ready for the next node
    publishes: tuple[str, ...] = ()  # recorded topics it publishes: recorded before the next node starts


class OfflineHarness:
    def __init__(self, workdir: Path, timeout: float = 60.0, stop_gap: float = 0.5) -> None:
        self.workdir = workdir
        self.timeout = timeout
        self.stop_gap = stop_gap
        self.logs: dict[str, str] = {}

    def _recorder(self, name: str, topics: Iterable[str]) -> tuple[NodeProcess, Path]:
        bag = self.workdir / name
        rec = NodeProcess("recorder", *topics, "-o", str(bag), "--discovery-period", "0.1")
        rec.wait_for_output("recording to", self.timeout)
        return rec, bag

    def _start(self, spec: NodeSpec, rec: NodeProcess, recorded: list[str]) -> NodeProcess:
        proc = NodeProcess(spec.script, *spec.args)
        try:
            if spec.ready:
                proc.wait_for_output(spec.ready, self.timeout)
            for topic in spec.publishes:
                if topic in recorded:
                    rec.wait_for_output(f"recording {topic} ", self.timeout)
        except BaseException:
            proc.__exit__(None, None, None)
            raise
        return proc

    def _finish(
        self, name: str, rec: NodeProcess, procs: list[tuple[NodeSpec, NodeProcess]], settle: float
    ) -> None:
        try:
            for spec, proc in procs:
                if spec.runs_to_end:
                    assert proc.wait(self.timeout) == 0, proc.output
            time.sleep(settle)
            # Upstream first (nodes are started downstream first): each node takes what the
            # previous one published at shutdown before it is stopped in turn.
            for spec, proc in reversed(procs):
                if not spec.runs_to_end:
                    assert proc.stop(signal.SIGINT) == 0, proc.output
                    time.sleep(self.stop_gap)
            assert rec.stop(signal.SIGINT) == 0, rec.output
        finally:
            for i, (spec, proc) in enumerate(procs):
                proc.__exit__(None, None, None)
                self.logs[f"{name}:{i}:{spec.script}"] = proc.output
            rec.__exit__(None, None, None)
            self.logs[f"{name}:recorder"] = rec.output

    def record(
        self,
        name: str,
        topics: list[str],
        nodes: list[NodeSpec],
        settle: float = 1.0,
    ) -> Path:
        """A live session of ``nodes`` (started in this order) with ``topics`` recorded;
        returns the bag."""
        rec, bag = self._recorder(name, topics)
        procs: list[tuple[NodeSpec, NodeProcess]] = []
        try:
            for spec in nodes:
                procs.append((spec, self._start(spec, rec, topics)))
            for topic in topics:
                rec.wait_for_output(f"recording {topic} ", self.timeout)
        except BaseException:
            for _spec, proc in procs:
                proc.__exit__(None, None, None)
            rec.__exit__(None, None, None)
            raise
        self._finish(name, rec, procs, settle)
        return bag

    def replay(
        self,
        name: str,
        bag: Path,
        inputs: list[str],
        nodes: list[NodeSpec],
        outputs: list[str],
        settle: float = 1.5,
    ) -> Path:
        """Fresh ``nodes`` fed the ``inputs`` of ``bag``; returns the bag of their ``outputs``."""
        rec, out_bag = self._recorder(name, outputs)
        procs: list[tuple[NodeSpec, NodeProcess]] = []
        try:
            for spec in nodes:
                procs.append((spec, self._start(spec, rec, outputs)))
            for topic in outputs:
                rec.wait_for_output(f"recording {topic} ", self.timeout)
            with NodeProcess(
                "replayer",
                str(bag),
                "--rate",
                "0",
                "--topics",
                *inputs,
                "--wait-for-subscribers",
                str(self.timeout),
                "--delay",
                "0.5",
            ) as player:
                code = player.wait(self.timeout)
                self.logs[f"{name}:replayer"] = player.output
                assert code == 0, player.output
        except BaseException:
            for _spec, proc in procs:
                proc.__exit__(None, None, None)
            rec.__exit__(None, None, None)
            raise
        self._finish(name, rec, procs, settle)
        return out_bag

    @staticmethod
    def decoded(bag: Path, topic: str, decode: Callable[[bytes], Any]) -> list[tuple[int, Any]]:
        """``(receive time ns, decoded message)`` of one topic, in order."""
        return [(m.log_time_ns, decode(m.data)) for m in BagReader(bag).messages([topic])]

    @classmethod
    def assert_same(
        cls,
        bag_a: Path,
        bag_b: Path,
        topics: dict[str, str],
        decode: Callable[[bytes], Any],
        equal: Callable[[Any, Any], bool],
    ) -> int:
        """Topic ``a`` of ``bag_a`` holds the same messages, in order, as topic ``b`` of
        ``bag_b`` for each ``a: b`` of ``topics``; returns how many messages were compared."""
        compared = 0
        for ta, tb in topics.items():
            xs = [m for _, m in cls.decoded(bag_a, ta, decode)]
            ys = [m for _, m in cls.decoded(bag_b, tb, decode)]
            assert len(xs) == len(ys), (
                f"{ta}: {len(xs)} messages in {bag_a.name}, {tb}: {len(ys)} in {bag_b.name}"
            )
            for i, (x, y) in enumerate(zip(xs, ys, strict=True)):
                assert equal(x, y), f"message {i} of {ta} differs between {bag_a.name} and {bag_b.name}"
            compared += len(xs)
        return compared
