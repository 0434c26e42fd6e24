"""The video streamer's logic on a virtual clock: screens, files, swaps, errors, previews, displays."""

from __future__ import annotations

import logging
import math
import threading
import types
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from audio_video_streamers.requests import parse_video_request
from audio_video_streamers.status import MediaStatus, State
from audio_video_streamers.video import render
from audio_video_streamers.video.display import (
    DisplayError,
    OffscreenDisplay,
    WindowDisplay,
    open_display,
)
from audio_video_streamers.video.player import WALL_RATE_CAP, VideoPlayer
from audio_video_streamers.video.preview import decode_jpeg, encode_jpeg
from audio_video_streamers.video.sources import FileVideo
from helpers.media import VirtualClock, capture_logger, green_mask, index_of_gray, write_video

SIZE = (320, 240)


class Rig:
    def __init__(self, tmp: Path, *, preview_rate: float = 1.0, fps: float = 30.0) -> None:
        self.clock = VirtualClock()
        self.log, self.logs = capture_logger("video")
        self.display = OffscreenDisplay()
        self.statuses: list[MediaStatus] = []
        self.previews: list[tuple[float, np.ndarray]] = []
        self.player = VideoPlayer(self.display, size=SIZE, fps=fps, preview_rate=preview_rate,
                                  clock=self.clock, on_status=self.statuses.append,
                                  on_preview=lambda frame, t: self.previews.append((t, frame)),
                                  media_dir=tmp, log=self.log, wall=self.clock, sleep=self.clock.sleep)
        self.stop = threading.Event()

    def show(self, text: str) -> None:
        self.player.request(text)
        assert self.player.step(self.stop)  # applied at the next frame

    def frames(self, count: int) -> list[tuple[dict, np.ndarray]]:
        out = []
        for _ in range(count):
            assert self.player.step(self.stop)
            out.append((self.player.status().as_dict(), self.display.last))
        return out


# ----------------------------------------------------------------------------------------------
# Built-in screens
def trace_head(frame: np.ndarray) -> int:
    """The right-most column of the bright (current) sweep of the trace."""
    bright = green_mask(frame) & (frame[..., 1] > 200)
    columns = np.nonzero(bright.any(axis=0))[0]
    assert len(columns), "no bright green trace on the splash"
    return int(columns.max())


def test_the_splash_trace_sweeps_across_the_screen(tmp_path: Path) -> None:
    rig = Rig(tmp_path, preview_rate=1.0)
    rig.player.request("splash")
    for _ in range(75):  # 2.5 s at 30 fps: three previews
        rig.player.step(rig.stop)
    assert len(rig.previews) == 3
    assert [round(t - rig.previews[0][0], 3) for t, _ in rig.previews] == [0.0, 1.0, 2.0]
    frames = [decode_jpeg(encode_jpeg(frame)) for _, frame in rig.previews]  # as a viewer gets them
    # At 0 s the new sweep has not begun (only the fading previous one shows); then it moves right,
    # a quarter of the width per second.
    heads = [trace_head(f) for f in frames[1:]]
    assert heads[0] < heads[1]
    assert heads[0] == pytest.approx(SIZE[0] / render.SWEEP_PERIOD, abs=12)
    assert heads[1] - heads[0] == pytest.approx(SIZE[0] / render.SWEEP_PERIOD, abs=12)
    masks = [green_mask(f) for f in frames]
    assert (masks[0] != masks[1]).sum() > 200  # the green pixels changed between two previews
    # The title is there: light pixels in the upper half that are not green.
    upper = frames[0][: SIZE[1] // 2]
    assert (upper.min(axis=2) > 200).sum() > 300
    status = rig.statuses[-1]
    assert (status.state, status.source, status.kind) == (State.PLAYING, "splash", "splash")


def test_the_splash_wraps_around_after_a_sweep() -> None:
    img = render.blank(*SIZE)
    late = trace_head(render.draw_splash(img, render.SWEEP_PERIOD * 0.9).copy())
    early = trace_head(render.draw_splash(img, render.SWEEP_PERIOD * 1.1).copy())
    assert early < late
    assert render.sweep_head(render.SWEEP_PERIOD * 1.1, SIZE[0]) == pytest.approx(0.1 * SIZE[0], abs=1)


@pytest.mark.parametrize("activity", ["marching", "step_up", "lateral", "arms_forward"])
def test_activity_placeholders_move_at_the_tempo(activity: str) -> None:
    """At 120 BPM the figure repeats every 2 beats (1 s; step_up every 4 beats) and differs in between."""
    cycle = 2.0 if activity == "step_up" else 1.0

    def at(t: float) -> np.ndarray:
        return render.draw_activity(render.blank(*SIZE), activity, t, 120.0)

    figure = (slice(0, SIZE[1]), slice(0, int(0.62 * SIZE[0])))  # the figure's half, not the metronome
    assert np.array_equal(at(0.3)[figure], at(0.3 + cycle)[figure])
    assert not np.array_equal(at(0.3)[figure], at(0.3 + cycle / 2)[figure])
    # The metronome swings once per beat: the same at 0.25 s and 0.25 + 1 beat (0.5 s) mirrored, and a
    # tempo change changes the picture at the same time.
    assert not np.array_equal(at(0.25), render.draw_activity(render.blank(*SIZE), activity, 0.25, 90.0))


def test_activities_follow_the_audio_tempo_unless_the_request_names_one(tmp_path: Path) -> None:
    rig = Rig(tmp_path)
    rig.show("marching")
    assert rig.player.status().tempo == 120.0  # the default until the audio streamer reports one
    rig.player.set_audio_tempo(132.0)
    rig.frames(1)
    assert rig.player.status().tempo == 132.0
    assert rig.statuses[-1].tempo == 132.0  # a tempo change is a status change
    rig.show("lateral@100")
    rig.player.set_audio_tempo(125.0)
    rig.frames(1)
    assert rig.player.status().tempo == 100.0
    rig.show("relaxing")
    assert rig.player.status().tempo is None


def stepping_sim_clock(wall: VirtualClock, step: float = 0.125) -> Callable[[], float]:
    """Sim time at real time as /clock gives it: it moves in steps of ``step`` s (binary fractions here,
    so frame times fall exactly on steps)."""
    return lambda: 5000.0 + math.floor(wall() / step) * step


def test_an_unchanged_picture_is_not_drawn_again(tmp_path: Path) -> None:
    """Sim time at 1x moves in steps: of the 4 frames a step spans, only the first is drawn."""
    wall = VirtualClock(0.0)
    display = OffscreenDisplay()
    player = VideoPlayer(display, size=SIZE, fps=32.0, clock=stepping_sim_clock(wall), wall=wall,
                         sleep=wall.sleep)
    stop = threading.Event()
    player.request("marching")
    times, pictures = [], []
    for _ in range(32):
        assert player.step(stop)
        times.append(player.status().elapsed)
        pictures.append(display.last.copy())
    assert display.shown == 32
    assert player.drawn == len(set(times)) <= 10  # one drawing per clock step, not per frame
    for elapsed, picture in zip(times, pictures, strict=True):  # and each frame is its time's picture
        assert np.array_equal(picture, render.draw_activity(render.blank(*SIZE), "marching", elapsed, 120.0))
    player.set_audio_tempo(90.0)  # a new tempo is a new picture at the same time
    before = player.drawn
    player.step(stop)
    assert player.drawn == before + 1


def test_an_unwatched_display_draws_only_the_previews(tmp_path: Path) -> None:
    def run(display: OffscreenDisplay) -> tuple[VideoPlayer, list[tuple[float, np.ndarray]]]:
        wall = VirtualClock(0.0)
        previews: list[tuple[float, np.ndarray]] = []
        player = VideoPlayer(display, size=SIZE, fps=30.0, preview_rate=1.0, clock=wall, wall=wall,
                             sleep=wall.sleep, on_preview=lambda frame, t: previews.append((t, frame)))
        player.request("splash")
        for _ in range(90):  # 3 s
            assert player.step(threading.Event())
        return player, previews

    watched, seen = run(OffscreenDisplay())
    unwatched, unseen = run(OffscreenDisplay(watched=False))
    assert unwatched.drawn == len(unseen) == len(seen) == 4 and watched.drawn == 90
    assert [t for t, _ in unseen] == [t for t, _ in seen]  # the same previews, pixel for pixel
    assert all(np.array_equal(a, b) for (_, a), (_, b) in zip(unseen, seen, strict=True))
    assert unwatched.display.shown == watched.display.shown == 90  # at the same pace
    assert unwatched.status().extra["shown"] == 90
    assert isinstance(open_display("offscreen", capture_logger("d")[0]), OffscreenDisplay)
    assert not open_display("offscreen", capture_logger("d")[0]).watched


def test_an_unwatched_display_still_reads_every_frame_of_a_file(tmp_path: Path) -> None:
    """A file is decoded in order (its position is in the status): its frames are read unwatched too."""
    write_video(tmp_path / "twelve.avi", 12, 24.0)
    clock = VirtualClock()
    display = OffscreenDisplay(watched=False)
    player = VideoPlayer(display, size=SIZE, preview_rate=0.0, clock=clock, wall=clock, sleep=clock.sleep,
                         media_dir=tmp_path)
    player.request("twelve.avi")
    stop = threading.Event()
    frames = []
    for _ in range(14):
        player.step(stop)
        frames.append(player.status().extra["frame"])
    assert frames == [*range(12), 0, 1] and index_of_gray(display.last) == 1


# ----------------------------------------------------------------------------------------------
# Files
def test_a_file_plays_at_its_rate_loops_and_swaps(tmp_path: Path) -> None:
    write_video(tmp_path / "twelve.avi", 12, 24.0)
    write_video(tmp_path / "other.avi", 5, 10.0, size=(80, 80))
    rig = Rig(tmp_path)
    rig.show("twelve.avi")
    shown = rig.frames(40)
    indexes = [s["frame"] for s, _ in shown]
    assert indexes[:11] == list(range(1, 12))  # every frame once, in order, at 24 fps
    assert indexes[11] == 0 and max(indexes) == 11  # the index wraps at the end
    assert [index_of_gray(f) for _, f in shown] == indexes  # and the pixels are those frames
    assert shown[-1][0]["loops"] == 3 and shown[-1][0]["frames"] == 12
    assert shown[-1][0]["fps"] == 24.0 and shown[-1][0]["duration"] == pytest.approx(0.5)
    loops = [s.loops for s in rig.statuses if s.source == "twelve.avi"]
    assert loops == sorted(loops) and {1, 2, 3} <= set(loops)  # every wrap published
    t_before = rig.clock()
    rig.show("other.avi")  # swaps at the next frame, no fade
    after = rig.display.last
    assert after.shape == (SIZE[1], SIZE[0], 3)  # letterboxed to the output size
    assert index_of_gray(after) == 0 and rig.player.status().source == "other.avi"
    assert rig.player.status().extra["fps"] == 10.0
    rig.frames(3)
    assert rig.clock() - t_before == pytest.approx(1 / 24 + 3 / 10, abs=1e-6)  # its own frame rate


def test_a_late_renderer_skips_frames_instead_of_rushing(tmp_path: Path) -> None:
    write_video(tmp_path / "twelve.avi", 12, 24.0)
    rig = Rig(tmp_path)
    rig.show("twelve.avi")
    rig.frames(2)
    rig.clock.t += 0.3  # the machine stalled for 0.3 s
    status, frame = rig.frames(1)[0]
    due_now = int((2 / 24 + 0.3) * 24)  # 9
    assert status["frame"] == due_now and index_of_gray(frame) == due_now  # not frame 3
    assert status["skipped"] == due_now - 3  # frames 3..8 were never shown


def test_the_source_time_goes_on_when_the_clock_goes_back_or_starts(tmp_path: Path) -> None:
    write_video(tmp_path / "twelve.avi", 12, 24.0)
    wall = VirtualClock(0.0)
    offset = [1000.0]
    sim = lambda: offset[0] + wall()  # noqa: E731  (ROS time following wall time, until it jumps)
    player = VideoPlayer(OffscreenDisplay(), size=SIZE, clock=sim, wall=wall, sleep=wall.sleep,
                         media_dir=tmp_path)
    stop = threading.Event()
    player.request("twelve.avi")
    for _ in range(4):
        player.step(stop)
    before = player.status().elapsed
    offset[0] -= 500.0  # a replay restarted
    player.step(stop)
    assert player.status().elapsed == pytest.approx(before + 1 / 24, abs=1e-3)
    assert player.status().extra["frame"] == 4

    sim_time = VirtualClock(0.0)  # use_sim_time before the first /clock: ROS time reads 0
    player = VideoPlayer(OffscreenDisplay(), size=SIZE, clock=sim_time, wall=sim_time, sleep=sim_time.sleep)
    player.request("splash")
    player.step(stop)
    sim_time.t = 1_700_000_000.0  # /clock arrives
    player.step(stop)
    player.step(stop)
    status = player.status()
    assert status.elapsed < 0.1 and status.extra["skipped"] == 0


def test_a_fast_simulation_shows_the_picture_due_without_rendering_every_frame(tmp_path: Path) -> None:
    """Sim time at 30x: at most WALL_RATE_CAP x 30 frames per wall second, each the one due in sim time."""
    write_video(tmp_path / "twelve.avi", 12, 24.0)
    wall = VirtualClock(0.0)
    sim = lambda: 5000.0 + 30.0 * wall()  # noqa: E731
    display = OffscreenDisplay()
    player = VideoPlayer(display, size=SIZE, clock=sim, wall=wall, sleep=wall.sleep, media_dir=tmp_path)
    stop = threading.Event()
    player.request("twelve.avi")
    for _ in range(40):
        player.step(stop)
        status = player.status()
        assert index_of_gray(display.last) == int(status.elapsed * 24 + 1e-6) % 12  # the frame due
    assert wall() == pytest.approx(39 / (24 * WALL_RATE_CAP), rel=0.05)  # 40 frames took ~1.2 wall s
    assert status.elapsed == pytest.approx(30 * wall(), rel=0.05)  # but 37 s of sim time
    assert status.extra["skipped"] > 30 * 24 * wall() * 0.9


def test_bad_video_requests_report_errors_and_the_video_goes_on(tmp_path: Path) -> None:
    write_video(tmp_path / "twelve.avi", 12, 24.0)
    (tmp_path / "broken.mp4").write_text("not a video")
    rig = Rig(tmp_path)
    rig.show("twelve.avi")
    bad = ["missing.mp4", "broken.mp4", "youtube:abc", "marching@0", ""]
    for text in bad:
        rig.show(text)
    errors = [s for s in rig.statuses if s.state == State.ERROR]
    assert [e.request for e in errors] == bad
    assert all(e.source == "twelve.avi" and e.error for e in errors)
    assert len(rig.logs.messages(logging.ERROR)) == len(bad)
    status = rig.player.status()
    assert (status.state, status.source) == (State.PLAYING, "twelve.avi")
    assert (status.requests.received, status.requests.started, status.requests.failed) == (6, 1, 5)
    assert [s["frame"] for s, _ in rig.frames(3)] == [6, 7, 8]  # one frame per step all along


def test_a_file_announcing_too_many_frames_still_loops(tmp_path: Path) -> None:
    path = write_video(tmp_path / "six.avi", 6, 24.0)

    class Overcounting:
        def __init__(self, name: str) -> None:
            import cv2

            self.cap = cv2.VideoCapture(name)

        def get(self, prop: int) -> float:
            import cv2

            return 60.0 if prop == cv2.CAP_PROP_FRAME_COUNT else self.cap.get(prop)

        def __getattr__(self, name: str) -> object:
            return getattr(self.cap, name)

    video = FileVideo(parse_video_request(str(path)), SIZE, capture=Overcounting)
    seen = [index_of_gray(video.frame(k / 24)) for k in range(14)]
    assert seen == [0, 1, 2, 3, 4, 5, 0, 1, 2, 3, 4, 5, 0, 1]
    assert video.frames == 6


# ----------------------------------------------------------------------------------------------
# Displays
def test_no_display_server_renders_offscreen_with_one_info_line() -> None:
    log, logs = capture_logger("display")
    assert isinstance(open_display("auto", log, env={}), OffscreenDisplay)
    assert len(logs.messages()) == 1 and logs.records[0].levelno == logging.INFO
    with pytest.raises(DisplayError, match="no display server"):
        open_display("window", log, env={})
    assert isinstance(open_display("offscreen", log, env={"DISPLAY": ":0"}), OffscreenDisplay)


def test_headless_opencv_cannot_open_a_window_so_auto_renders_offscreen() -> None:
    import cv2

    log, logs = capture_logger("headless")
    display = open_display("auto", log, env={"DISPLAY": ":0"}, backend=cv2)
    try:
        cv2.namedWindow("probe")
        has_gui = True
        cv2.destroyWindow("probe")
    except cv2.error:
        has_gui = False
    if not has_gui:
        assert isinstance(display, OffscreenDisplay) and "window" in logs.messages()[0]
        with pytest.raises(DisplayError, match="cannot open a window"):
            open_display("window", log, env={"DISPLAY": ":0"}, backend=cv2)
    display.close()


def test_a_window_shows_every_frame() -> None:
    calls: list[tuple] = []
    fake = types.ModuleType("cv2")
    fake.error = RuntimeError  # type: ignore[attr-defined]
    fake.WINDOW_NORMAL, fake.WND_PROP_FULLSCREEN, fake.WINDOW_FULLSCREEN = 0, 1, 1  # type: ignore[attr-defined]
    for name in ("namedWindow", "setWindowProperty", "imshow", "waitKey", "destroyWindow"):
        setattr(fake, name, lambda *args, _n=name: calls.append((_n, *args[:1])))
    log, _ = capture_logger("window")
    display = open_display("window", log, fullscreen=True, env={"WAYLAND_DISPLAY": "wayland-0"}, backend=fake)
    assert isinstance(display, WindowDisplay)
    frame = np.zeros((4, 4, 3), dtype=np.uint8)
    display.show(frame)
    display.show(frame)
    display.close()
    names = [c[0] for c in calls]
    assert names == ["namedWindow", "setWindowProperty", "imshow", "waitKey", "imshow", "waitKey",
                     "destroyWindow"]
    assert display.shown == 2


def test_previews_off_and_at_a_higher_rate(tmp_path: Path) -> None:
    off = Rig(tmp_path, preview_rate=0.0)
    off.show("splash")
    off.frames(60)
    assert off.previews == []
    fast = Rig(tmp_path, preview_rate=5.0)
    fast.show("splash")
    fast.frames(59)  # 2 s at 30 fps
    assert len(fast.previews) == 10
    assert fast.previews[0][1].shape == (SIZE[1], SIZE[0], 3)
