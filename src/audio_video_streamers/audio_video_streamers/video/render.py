"""The built-in screens, drawn with OpenCV so the demo needs no video files.

- :func:`draw_splash`: the project's name over a green ECG trace sweeping across a dark
  screen, as on a patient monitor.
- :func:`draw_relaxing`: a circle that grows and shrinks at a slow breathing pace.
- :func:`draw_activity`: the activity's name, a stick figure doing it and a metronome, both
  moving at the current tempo (one step per beat).

Every function draws frame ``elapsed`` seconds into the screen on a BGR canvas (H, W, 3).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache

import cv2
import numpy as np

BACKGROUND = (22, 16, 12)  # BGR, near black with a blue tint
TEXT = (235, 235, 235)
DIM_TEXT = (150, 150, 150)
GREEN = (90, 235, 70)  # BGR
AMBER = (40, 190, 250)
SWEEP_PERIOD = 4.0  # s for the trace to cross the screen
BREATH_PERIOD = 10.0  # s per breath (6 per minute)
FONT = cv2.FONT_HERSHEY_DUPLEX

ACTIVITY_LABELS = {
    "marching": "Marching",
    "step_up": "Step-up, reach and pull",
    "lateral": "Lateral knee lifts",
    "arms_forward": "Both arms forward",
}


#: One heartbeat as (centre in s after the beat's start, width in s, height): P, Q, R, S, T waves.
_WAVES = ((0.16, 0.025, 0.12), (0.265, 0.010, -0.12), (0.29, 0.012, 1.0), (0.315, 0.010, -0.25),
          (0.55, 0.045, 0.28))


@cache
def ecg_trace(rate: int = 250, heart_rate: float = 72.0, beats: int = 12) -> np.ndarray:
    """A clean ECG-like trace (whole beats, so it loops), peak 1.

    Drawn from Gaussian P-QRS-T waves rather than simulated: the splash must appear at once,
    and importing a physiology library takes seconds in a fresh process.
    """
    period = 60.0 / heart_rate
    t = (np.arange(round(beats * period * rate)) / rate) % period
    trace = sum(h * np.exp(-0.5 * ((t - c) / w) ** 2) for c, w, h in _WAVES)
    return np.asarray(trace) / np.max(np.abs(trace))


def blank(width: int, height: int) -> np.ndarray:
    return np.full((height, width, 3), BACKGROUND, dtype=np.uint8)


@cache
def _static_layer(kind: str, width: int, height: int, text: str) -> np.ndarray:
    """What does not move on a screen (background, titles), drawn once and copied into every frame."""
    img = blank(width, height)
    if kind == "splash":
        put_centred(img, text, int(0.30 * height), 0.8 * width, TEXT, scale=3.0, thickness=3)
        put_centred(img, "heart-rate aware exercise coach", int(0.30 * height) + max(24, height // 12),
                    0.7 * width, DIM_TEXT, scale=1.0, thickness=1)
    elif kind == "activity":
        put_centred(img, ACTIVITY_LABELS.get(text, text), int(0.14 * height), 0.9 * width, TEXT,
                    scale=1.6, thickness=2)
    img.flags.writeable = False
    return img


def _start_frame(img: np.ndarray, kind: str, text: str = "") -> None:
    np.copyto(img, _static_layer(kind, img.shape[1], img.shape[0], text))


def put_centred(img: np.ndarray, text: str, y: int, max_width: float, color: tuple[int, int, int],
                scale: float = 3.0, thickness: int = 2) -> None:
    """``text`` centred at baseline ``y``, shrunk to fit ``max_width`` pixels."""
    (w, _), _ = cv2.getTextSize(text, FONT, scale, thickness)
    if w > max_width:
        scale *= max_width / w
        (w, _), _ = cv2.getTextSize(text, FONT, scale, thickness)
    cv2.putText(img, text, ((img.shape[1] - w) // 2, y), FONT, scale, color, thickness, cv2.LINE_AA)


# ----------------------------------------------------------------------------------------------
# Splash
def sweep_head(elapsed: float, width: int) -> int:
    """The column the trace has reached ``elapsed`` s into the splash."""
    return int((elapsed % SWEEP_PERIOD) / SWEEP_PERIOD * width)


def _trace(img: np.ndarray, x: np.ndarray, y: np.ndarray, color: tuple[int, ...]) -> None:
    """An anti-aliased polyline through (x, y), flat runs merged first (the flat line costs the most)."""
    points = np.stack([x, y], axis=1).astype(np.int32).reshape(-1, 1, 2)
    cv2.polylines(img, [cv2.approxPolyDP(points, 0.6, False)], False, color, 2, cv2.LINE_AA)


def draw_splash(img: np.ndarray, elapsed: float, title: str = "HRI Physio") -> np.ndarray:
    h, w = img.shape[:2]
    _start_frame(img, "splash", title)

    trace = ecg_trace()
    rate = 250
    sweep = int(elapsed // SWEEP_PERIOD)
    head = sweep_head(elapsed, w)
    centre, amp = int(0.68 * h), 0.16 * h
    cols = np.arange(w)

    def ys(k: int) -> np.ndarray:
        t = (k * SWEEP_PERIOD + cols / w * SWEEP_PERIOD) * rate
        return centre - amp * np.interp(t % len(trace), np.arange(len(trace)), trace)

    gap = max(4, w // 40)  # the erased band ahead of the head
    now, before = ys(sweep), ys(sweep - 1)
    if head + gap < w:  # the previous sweep, fading, right of the head
        _trace(img, cols[head + gap:], before[head + gap:], tuple(int(c * 0.45) for c in GREEN))
    if head > 0:
        _trace(img, cols[: head + 1], now[: head + 1], GREEN)
    cv2.circle(img, (head, int(now[min(head, w - 1)])), 4, (200, 255, 200), -1, cv2.LINE_AA)
    return img


# ----------------------------------------------------------------------------------------------
# Relaxing
def draw_relaxing(img: np.ndarray, elapsed: float) -> np.ndarray:
    h, w = img.shape[:2]
    _start_frame(img, "blank")
    phase = (elapsed % BREATH_PERIOD) / BREATH_PERIOD
    size = 0.5 - 0.5 * math.cos(2 * math.pi * phase)  # 0 -> 1 -> 0 over a breath
    radius = int((0.12 + 0.18 * size) * min(w, h))
    cv2.circle(img, (w // 2, int(0.55 * h)), radius, (160, 120, 60), -1, cv2.LINE_AA)
    cv2.circle(img, (w // 2, int(0.55 * h)), int(0.30 * min(w, h)), (110, 90, 60), 2, cv2.LINE_AA)
    put_centred(img, "breathe in" if phase < 0.5 else "breathe out", int(0.15 * h), 0.6 * w, TEXT,
                scale=1.6, thickness=2)
    return img


# ----------------------------------------------------------------------------------------------
# Activities
@dataclass(frozen=True)
class Pose:
    """Absolute limb angles in degrees from straight down, positive towards +x (the way it faces)."""

    thigh: tuple[float, float] = (0.0, 0.0)  # (near leg, far leg)
    shin: tuple[float, float] = (0.0, 0.0)
    arm: tuple[float, float] = (10.0, -10.0)
    forearm: tuple[float, float] = (20.0, -5.0)
    lift: float = 0.0  # 0 on the ground .. 1 standing on the step


def _towards(point: np.ndarray, angle: float, length: float) -> np.ndarray:
    a = math.radians(angle)
    return point + length * np.array([math.sin(a), math.cos(a)])


def pose_for(activity: str, beats: float) -> Pose:
    """The figure's pose ``beats`` beats into the activity (a left and a right step: 2 beats)."""
    s = math.sin(math.pi * beats)
    near, far = max(0.0, s), max(0.0, -s)
    if activity == "marching":
        return Pose(thigh=(70 * near, 70 * far), shin=(70 * near - 75 * near, 70 * far - 75 * far),
                    arm=(-35 * s, 35 * s), forearm=(-35 * s + 40, 35 * s + 40))
    if activity == "step_up":
        cycle = (beats % 4.0) / 4.0  # up, up, down, down
        lift = 0.5 - 0.5 * math.cos(2 * math.pi * cycle)
        reach = 170 * lift
        return Pose(thigh=(60 * near, 60 * far), shin=(60 * near - 70 * near, 60 * far - 70 * far),
                    arm=(reach, reach - 10), forearm=(reach, reach - 10), lift=lift)
    if activity == "lateral":  # seen from the front: knees out to either side
        return Pose(thigh=(-65 * near, 65 * far), shin=(-10 * near, 10 * far),
                    arm=(-100 + 40 * near, 100 - 40 * far), forearm=(-170 + 60 * near, 170 - 60 * far))
    if activity == "arms_forward":
        reach = 90 * (0.5 - 0.5 * math.cos(math.pi * beats))  # forward on every beat, down between
        return Pose(thigh=(25 * near, 25 * far), shin=(0.0, 0.0), arm=(reach, reach - 5),
                    forearm=(reach, reach - 5))
    return Pose()


STEP_RISE = 0.17  # of the figure's height
STEP_ADVANCE = 0.28


def draw_figure(img: np.ndarray, ground: tuple[int, int], height: float, pose: Pose,
                color: tuple[int, int, int] = TEXT) -> None:
    """A stick figure standing on ``ground`` (x, y), ``height`` pixels tall, in ``pose``.

    With ``pose.lift`` the figure moves forward and up onto a step ``STEP_RISE`` high.
    """
    leg, torso, upper, lower = 0.24 * height, 0.32 * height, 0.16 * height, 0.15 * height
    head_r = int(0.07 * height)
    hip = np.array([ground[0] + pose.lift * STEP_ADVANCE * height,
                    ground[1] - 2 * leg - pose.lift * STEP_RISE * height], dtype=float)
    neck = hip + np.array([0.0, -torso])
    thick = max(2, int(height / 45))

    def line(a: np.ndarray, b: np.ndarray, c: tuple[int, int, int] = color) -> None:
        cv2.line(img, tuple(int(v) for v in a), tuple(int(v) for v in b), c, thick, cv2.LINE_AA)

    far = tuple(int(v * 0.6) for v in color)
    for i, c in ((1, far), (0, color)):  # far limbs first, dimmer
        knee = _towards(hip, pose.thigh[i], leg)
        line(hip, knee, c)
        line(knee, _towards(knee, pose.shin[i], leg), c)
        elbow = _towards(neck, pose.arm[i], upper)
        line(neck, elbow, c)
        line(elbow, _towards(elbow, pose.forearm[i], lower), c)
    line(hip, neck)
    cv2.circle(img, (int(neck[0]), int(neck[1] - head_r * 1.3)), head_r, color, thick, cv2.LINE_AA)


def draw_metronome(img: np.ndarray, centre: tuple[int, int], size: float, beats: float) -> None:
    """A pendulum at one end of its swing on every beat, and a count of four that lights on the beat."""
    x, y = centre
    body = np.array([[x - 0.35 * size, y], [x + 0.35 * size, y], [x + 0.15 * size, y - size],
                     [x - 0.15 * size, y - size]], dtype=np.int32)
    cv2.polylines(img, [body], True, DIM_TEXT, 2, cv2.LINE_AA)
    angle = 28.0 * math.cos(math.pi * beats)  # extreme on every beat
    tip = _towards(np.array([x, y - 0.1 * size], dtype=float), 180 + angle, 0.95 * size)
    cv2.line(img, (x, int(y - 0.1 * size)), (int(tip[0]), int(tip[1])), AMBER, 3, cv2.LINE_AA)
    cv2.circle(img, (int(tip[0]), int(tip[1])), max(3, int(0.05 * size)), AMBER, -1, cv2.LINE_AA)
    count, on_beat = int(beats) % 4, (beats % 1.0) < 0.2
    for i in range(4):
        radius = max(3, int(0.045 * size)) * (2 if i == count and on_beat else 1)
        cx = int(x + (i - 1.5) * 0.3 * size)
        cv2.circle(img, (cx, int(y + 0.28 * size)), radius, AMBER if i == count else DIM_TEXT, -1,
                   cv2.LINE_AA)


def draw_activity(img: np.ndarray, activity: str, elapsed: float, tempo: float) -> np.ndarray:
    h, w = img.shape[:2]
    _start_frame(img, "activity", activity)
    beats = elapsed * tempo / 60.0
    ground_y, figure = int(0.92 * h), 0.58 * h
    x0 = int(0.3 * w) - (int(0.12 * figure) if activity == "step_up" else 0)
    cv2.line(img, (int(0.05 * w), ground_y), (int(0.6 * w), ground_y), DIM_TEXT, 2)
    if activity == "step_up":
        cv2.rectangle(img, (x0 + int(0.14 * figure), ground_y - int(STEP_RISE * figure)),
                      (x0 + int(0.45 * figure), ground_y), DIM_TEXT, 2)
    draw_figure(img, (x0, ground_y), figure, pose_for(activity, beats))
    draw_metronome(img, (int(0.8 * w), int(0.68 * h)), 0.36 * h, beats)
    put_centred_at(img, f"{tempo:.0f} BPM", (int(0.8 * w), int(0.26 * h)), TEXT)
    return img


def put_centred_at(img: np.ndarray, text: str, at: tuple[int, int], color: tuple[int, int, int]) -> None:
    (tw, _), _ = cv2.getTextSize(text, FONT, 1.0, 2)
    cv2.putText(img, text, (at[0] - tw // 2, at[1]), FONT, 1.0, color, 2, cv2.LINE_AA)
