"""Test helper: running a PolarSession against fake devices in virtual time."""

from __future__ import annotations

import asyncio
import random
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from hri_physio_bridge.polar.config import PolarConfig
from hri_physio_bridge.polar.fake import FakeClock, FakePolarDevice, FakeScanner, fake_client_factory
from hri_physio_bridge.polar.output import MemorySink
from hri_physio_bridge.polar.session import PolarSession
from hri_physio_bridge.polar.synthetic import SyntheticH10, synthetic_h10
from hri_physio_bridge.polar.virtual_time import run_virtual

NAME = "Polar H10 0A1B2C3D"
#: FakePolarDevice options that h10() passes to the device (the rest go to synthetic_h10).
DEVICE_OPTIONS = (
    "disconnect_after", "connect_failures", "pairing_required", "stop_indication_after", "start_status",
    "visible", "start_params", "mtu", "invalid_mtu_answers", "unnamed_errors", "stall_after", "stall_heals",
    "start_delays",
)

#: How often (virtual seconds) the driver checks its stop condition.
POLL = 0.05


def h10(clock: FakeClock, seconds: float = 30.0, **kwargs: Any) -> tuple[FakePolarDevice, SyntheticH10]:
    """A fake H10 streaming ``seconds`` of synthetic data; device faults by name (``DEVICE_OPTIONS``)."""
    device_options = {k: kwargs.pop(k) for k in DEVICE_OPTIONS if k in kwargs}
    syn = synthetic_h10(seconds, **kwargs)
    device = FakePolarDevice(
        NAME, features=syn.features, settings=syn.settings, timeline=syn.timeline, clock=clock,
        **device_options,
    )
    return device, syn


def writes(device: FakePolarDevice) -> list[str]:
    """The hex of every write the device received, in order."""
    return [op[2] for op in device.operations if op[0] == "write"]


@dataclass
class Run:
    status: int
    session: PolarSession
    sink: Any
    devices: list[FakePolarDevice]
    events: list[dict[str, Any]] = field(default_factory=list)
    sleeps: list[float] = field(default_factory=list)

    def of(self, event: str) -> list[dict[str, Any]]:
        return [e for e in self.events if e["event"] == event]

    @property
    def states(self) -> list[str]:
        return [e["state"] for e in self.of("state")]


def run_session(
    devices: list[FakePolarDevice],
    clock: FakeClock,
    sink: Any | None = None,
    *,
    stop_when: Callable[[PolarSession, list[dict[str, Any]]], bool] | None = None,
    max_seconds: float = 100_000.0,
    **options: Any,
) -> Run:
    """Run a session in virtual time until ``stop_when`` holds (default: the first device's timeline
    is played), checked every ``POLL`` virtual seconds; fails after ``max_seconds`` of virtual time."""
    config = PolarConfig(**options)
    sink = sink if sink is not None else MemorySink()
    sleeps: list[float] = []

    async def sleep(seconds: float) -> None:
        sleeps.append(seconds)
        await clock.sleep(seconds)

    async def main() -> Run:
        session = PolarSession(
            config,
            FakeScanner(devices, clock),
            fake_client_factory,
            sink,
            clock=clock,
            sleep=sleep,
            rng=random.Random(7),
        )
        events: list[dict[str, Any]] = []

        def on_event(event: dict[str, Any]) -> None:
            events.append(event)
            if event["event"] == "state" and event.get("state") == "streaming":
                for device in devices:
                    if device.connected:
                        device.release()

        session.listeners.append(on_event)
        stop = asyncio.Event()
        task = asyncio.ensure_future(session.run(stop))
        done = stop_when or (lambda _s, _e: devices[0].finished)
        deadline = clock() + max_seconds
        while not task.done() and not done(session, events):
            await asyncio.sleep(POLL)
            assert clock() < deadline, (
                f"session did not reach the end; state {session.state}, events {events[-5:]}"
            )
        stop.set()
        status = await task
        return Run(status, session, sink, devices, events, sleeps)

    return run_virtual(main(), clock)


class SessionThread:
    """A session on real time and a real sink, run on an asyncio loop in a thread (LSL tests).

    ``with SessionThread(session) as runner:`` starts it; leaving the block stops it, joins the
    thread and closes the sink; ``runner.result`` then holds the exit status.
    """

    def __init__(self, session: PolarSession) -> None:
        self.session = session
        self.loop = asyncio.new_event_loop()
        self.streaming = threading.Event()
        self.result: list[int] = []
        self._stop = asyncio.Event()
        session.listeners.append(lambda e: self.streaming.set() if e.get("state") == "streaming" else None)
        self._thread = threading.Thread(
            target=lambda: self.result.append(self.loop.run_until_complete(session.run(self._stop))),
            daemon=True,
        )

    def call(self, function: Callable[[], Any]) -> None:
        """Run ``function`` on the session's loop (e.g. a fake device's ``release``)."""
        self.loop.call_soon_threadsafe(function)

    def __enter__(self) -> SessionThread:
        self._thread.start()
        assert self.streaming.wait(30), "the session did not start streaming"
        return self

    def __exit__(self, *_exc: object) -> None:
        self.loop.call_soon_threadsafe(self._stop.set)
        self._thread.join(30)
        self.session.sink.close()
