"""SIGINT/SIGTERM as one stop event, for node processes and launchers alike (no rclpy here)."""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable
from typing import Any


def install_stop_handlers(on_stop: Callable[[str], None] | None = None) -> threading.Event:
    """SIGINT/SIGTERM set the returned event (and call ``on_stop`` once) instead of raising."""
    stop = threading.Event()

    def handler(signum: int, _frame: Any) -> None:
        if stop.is_set():
            return
        stop.set()
        if on_stop is not None:
            on_stop(signal.Signals(signum).name)

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
    return stop
