"""Where frames go: an OpenCV window on a display, or offscreen (no display, or ``display:=offscreen``).

OpenCV's headless build has no windows: creating one raises ``cv2.error``. ``auto`` shows a
window when a display server is set in the environment and OpenCV can open a window, and
otherwise renders offscreen (one info line). ``window`` insists and fails at start-up instead.
"""

from __future__ import annotations

import contextlib
import logging
import os
from collections.abc import Mapping
from types import ModuleType
from typing import Protocol

import cv2
import numpy as np

WINDOW_NAME = "HRI Physio"


class DisplayError(RuntimeError):
    """The requested display cannot be opened (one line)."""


class Display(Protocol):
    kind: str  # "window" | "offscreen"
    shown: int
    #: False: nobody sees the frames, so the player draws only those a preview needs and passes the
    #: others by with :meth:`skip` (they count as shown: the pace is the same).
    watched: bool

    def show(self, frame: np.ndarray) -> None: ...

    def skip(self) -> None: ...

    def close(self) -> None: ...


class OffscreenDisplay:
    """Keeps the last frame (what a screen would show) and counts frames.

    ``watched`` False is the node's offscreen display: nobody looks at it, so only the frames that
    go into a preview are drawn and :attr:`last` is the last of those.
    """

    kind = "offscreen"

    def __init__(self, watched: bool = True) -> None:
        self.last: np.ndarray | None = None
        self.shown = 0
        self.watched = watched

    def show(self, frame: np.ndarray) -> None:
        self.last = frame
        self.shown += 1

    def skip(self) -> None:
        self.shown += 1

    def close(self) -> None:
        pass


class WindowDisplay:
    """An OpenCV window (``backend`` is the cv2 module, a fake in tests)."""

    kind = "window"
    watched = True

    def __init__(self, backend: ModuleType = cv2, *, fullscreen: bool = False,
                 name: str = WINDOW_NAME) -> None:
        self.backend, self.name = backend, name
        try:
            backend.namedWindow(name, backend.WINDOW_NORMAL)
            if fullscreen:
                backend.setWindowProperty(name, backend.WND_PROP_FULLSCREEN, backend.WINDOW_FULLSCREEN)
        except backend.error as exc:
            raise DisplayError(f"cannot open a window: {str(exc).strip().splitlines()[-1]}") from None
        self.shown = 0

    def show(self, frame: np.ndarray) -> None:
        self.backend.imshow(self.name, frame)
        self.backend.waitKey(1)  # lets the window system draw it
        self.shown += 1

    def skip(self) -> None:  # a window is watched: the player never skips a frame of it
        self.shown += 1

    def close(self) -> None:
        with contextlib.suppress(self.backend.error):
            self.backend.destroyWindow(self.name)


def has_display_server(env: Mapping[str, str] = os.environ) -> bool:
    return bool(env.get("DISPLAY") or env.get("WAYLAND_DISPLAY"))


def open_display(mode: str, log: logging.Logger, *, fullscreen: bool = False,
                 env: Mapping[str, str] = os.environ, backend: ModuleType = cv2) -> Display:
    """The display ``mode`` asks for: ``auto``, ``window`` or ``offscreen`` (an unwatched one: the
    player draws only what its previews need)."""
    if mode == "offscreen":
        return OffscreenDisplay(watched=False)
    if not has_display_server(env):
        if mode == "window":
            raise DisplayError("display window: no display server (DISPLAY / WAYLAND_DISPLAY not set)")
        log.info("no display: rendering offscreen")
        return OffscreenDisplay(watched=False)
    try:
        return WindowDisplay(backend, fullscreen=fullscreen)
    except DisplayError as exc:
        if mode == "window":
            raise
        log.info(f"{exc}: rendering offscreen")
        return OffscreenDisplay(watched=False)
