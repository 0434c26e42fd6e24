"""The options of qt_controller and mock_qt_robot: declared once, checked without ROS."""

from __future__ import annotations

import pytest

from helpers import SRC
from hri_physio_bridge import topics
from hri_physio_bridge.config import ConfigError, load_yaml
from qt_controller.config import MockQtRobotConfig, QtControllerConfig, QtRobotOptions

CONFIG = SRC / "qt_controller" / "config"


@pytest.mark.parametrize("cls,name", [(QtControllerConfig, "qt_controller"),
                                      (MockQtRobotConfig, "mock_qt_robot")])
def test_shipped_config_files_hold_every_option_at_its_default(cls, name: str) -> None:
    values = load_yaml(CONFIG / f"{name}.yaml", name)
    assert set(values) == set(cls.model_fields)
    assert cls.from_mapping(values) == cls()


def test_defaults_are_safe_and_use_the_shared_topic_names() -> None:
    cfg = QtControllerConfig()
    assert cfg.allow_remote_exit is False  # anyone on the graph could stop the controller otherwise
    assert (cfg.input_topic, cfg.output_topic) == (topics.QT_COMMANDS, topics.QT_REPLIES)
    assert cfg.command_queue_limit >= 10_000
    assert set(cfg.robot_options()) == set(QtRobotOptions.model_fields)
    assert MockQtRobotConfig().events_topic == topics.QT_MOCK_EVENTS


@pytest.mark.parametrize("cls,values,option", [
    (QtControllerConfig, {"speech_channel": "shout"}, "speech_channel"),
    (QtControllerConfig, {"service_backend": "ros1"}, "service_backend"),
    (QtControllerConfig, {"service_timeout": -1}, "service_timeout"),
    (QtControllerConfig, {"joint_limits": "HeadYaw:9"}, "joint_limits"),
    (QtControllerConfig, {"joint_limits": "Nose:0:1"}, "joint_limits"),
    (QtControllerConfig, {"allow_remote_exit": "perhaps"}, "allow_remote_exit"),
    (QtControllerConfig, {"command_queue_limit": 0}, "command_queue_limit"),
    (QtControllerConfig, {"input_topic": ""}, "input_topic"),
    (QtControllerConfig, {"speech_chanel": "say"}, "speech_chanel"),
    (MockQtRobotConfig, {"emotion_seconds": 0}, "emotion_seconds"),
    (MockQtRobotConfig, {"default_velocity": 150}, "default_velocity"),
    (MockQtRobotConfig, {"default_volume": True}, "default_volume"),
    (MockQtRobotConfig, {"gesture_busy_policy": "queue"}, "gesture_busy_policy"),
    (MockQtRobotConfig, {"joint_state_rate": "fast"}, "joint_state_rate"),
])
def test_bad_values_name_the_option(cls, values: dict, option: str) -> None:
    with pytest.raises(ConfigError, match=option):
        cls.from_mapping(values)


def test_lists_from_text_and_yaml() -> None:
    emotions = QtControllerConfig.from_mapping({"extra_emotions": "QT/a, QT/b"}).extra_emotions
    assert emotions == ["QT/a", "QT/b"]
    assert MockQtRobotConfig.from_mapping({"gesture_dirs": ["x", "y"]}).gesture_dirs == ["x", "y"]


def test_the_mock_takes_its_settings_from_the_options_of_the_same_names() -> None:
    from qt_controller.mock_robot import MockConfig

    options = MockQtRobotConfig().replace(emotion_seconds=1.5, default_volume=20,
                                          gesture_busy_policy="refuse")
    mock = options.settings(MockConfig)
    assert (mock.emotion_seconds, mock.default_volume, mock.gesture_busy_policy) == (1.5, 20, "refuse")
    assert mock.default_speech_pitch == MockConfig.defaults().default_speech_pitch  # not an option: its own
    assert options.settings(MockConfig, default_volume=70).default_volume == 70  # an override wins
