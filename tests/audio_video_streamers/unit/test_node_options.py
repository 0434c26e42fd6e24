"""The streamers' options: one declaration drives flags, YAML and help; bad values are one line and status 2.

Nothing here starts ROS: run_node checks the options before rclpy.init.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from audio_video_streamers.audio.config import AudioStreamerConfig
from audio_video_streamers.nodes import audio_streamer, video_streamer
from audio_video_streamers.video.config import VideoStreamerConfig
from hri_physio_bridge.config import ConfigError


@pytest.mark.parametrize(
    ("main", "args", "fragment"),
    [
        (audio_streamer.main, ["--fade", "-1"], "fade"),
        (audio_streamer.main, ["--channels", "3"], "channels"),
        (audio_streamer.main, ["--rate", "abc"], "rate"),
        (audio_streamer.main, ["--latency", "0"], "latency"),
        (video_streamer.main, ["--preview-rate", "-1"], "preview_rate"),
        (video_streamer.main, ["--tempo", "20"], "tempo"),
        (video_streamer.main, ["--initial", ""], "initial"),
        (audio_streamer.main, ["--media-dir", "/nonexistent/music"],
         "media directory /nonexistent/music does not exist"),
        (video_streamer.main, ["--media-dir", __file__], "is not a directory"),
    ],
)
def test_bad_options_are_one_line_and_status_2(main, args: list[str], fragment: str,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and ": error:" in err and fragment in err, err


def test_defaults_run_without_hardware() -> None:
    audio = AudioStreamerConfig()
    assert (audio.sink, audio.fade, audio.rate, audio.record_wav) == ("auto", 1.0, 44100, "")
    video = VideoStreamerConfig()
    assert (video.display, video.preview_rate, video.initial, video.follow_audio) == ("auto", 1.0, "splash",
                                                                                        True)


def test_a_ros_params_file_configures_both(tmp_path: Path) -> None:
    params = tmp_path / "media.yaml"
    params.write_text("audio_streamer:\n  ros__parameters:\n    fade: 2.5\n    sink: 'null'\n"
                      "video_streamer:\n  ros__parameters:\n    display: offscreen\n    preview_rate: 0\n")
    assert AudioStreamerConfig.from_file(params, "audio_streamer").fade == 2.5
    assert VideoStreamerConfig.from_file(params, "video_streamer").preview_rate == 0.0
    with pytest.raises(ConfigError, match="unknown option"):
        AudioStreamerConfig.from_mapping({"volume": 3})


def test_the_packaged_example_files_hold_the_defaults() -> None:
    config = Path(audio_streamer.__file__).resolve().parents[2] / "config"
    audio = AudioStreamerConfig.from_file(config / "audio_streamer.yaml", "audio_streamer")
    video = VideoStreamerConfig.from_file(config / "video_streamer.yaml", "video_streamer")
    assert (audio, video) == (AudioStreamerConfig(), VideoStreamerConfig())


def test_help_lists_every_option(capsys: pytest.CaptureFixture[str]) -> None:
    for main, cls in ((audio_streamer.main, AudioStreamerConfig), (video_streamer.main, VideoStreamerConfig)):
        with pytest.raises(SystemExit) as exc:
            main(["--help"])
        assert exc.value.code == 0
        out = capsys.readouterr().out
        for name in cls.model_fields:
            assert "--" + name.replace("_", "-") in out
