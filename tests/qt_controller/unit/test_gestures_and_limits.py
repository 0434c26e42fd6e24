"""Gesture keyframe files (shipped and malformed), interpolation, speed maths and joint limits."""

from __future__ import annotations

from pathlib import Path

import pytest

from qt_controller.emotions import EmotionCatalogue, qt_emotion_name
from qt_controller.gestures import (
    GestureError,
    GestureLibrary,
    default_gesture_dir,
    load_gesture_file,
    parse_gesture_xml,
)
from qt_controller.joint_limits import (
    ALL_JOINTS,
    DEFAULT_LIMITS,
    HOME,
    JointLimitError,
    JointLimits,
    canonical_part,
    parse_limit_overrides,
)

EXERCISES = ("marching", "step_up", "lateral", "arms_forward", "base")


def gesture_xml(points: str, joints: str = "<joint>HeadYaw</joint><joint>HeadPitch</joint>",
                name: str = "nod") -> str:
    return f"<gesture><name>{name}</name><joints>{joints}</joints><points>{points}</points></gesture>"


def test_shipped_exercise_gestures_load_and_start_and_end_at_rest() -> None:
    lib = GestureLibrary.from_dirs([default_gesture_dir()])
    assert set(EXERCISES) <= set(lib.names)
    for name in EXERCISES:
        g = lib.get(name)
        assert g.duration > 1.0
        assert set(g.joints) <= set(ALL_JOINTS)
        start, end = g.positions_at(0.0), g.final_positions
        for j in g.joints:
            assert start[j] == HOME[j] and end[j] == HOME[j], (name, j)
        # It really moves: some joint leaves its rest position during the gesture.
        assert any(abs(row[k] - HOME[j]) >= 5 for row in g.positions for k, j in enumerate(g.joints)), name


def test_gestures_are_found_by_name_case_insensitively_and_unknown_is_an_error() -> None:
    lib = GestureLibrary.from_dirs([default_gesture_dir()])
    assert lib.get("MARCHING").name == "marching"
    assert "Lateral" in lib and "moonwalk" not in lib
    with pytest.raises(GestureError, match="unknown gesture 'moonwalk'; known: arms_forward"):
        lib.get("moonwalk")


def test_interpolation_and_speed_scaling() -> None:
    g = parse_gesture_xml(gesture_xml(
        '<point time="0">0 0</point><point time="2">40 -20</point><point time="4">0 0</point>'))
    assert g.duration == 4.0
    assert g.duration_at(1.0) == 4.0
    assert g.duration_at(0.9) == pytest.approx(4.0 / 0.9)
    assert g.duration_at(1.15) == pytest.approx(4.0 / 1.15)
    assert g.positions_at(1.0) == {"HeadYaw": 20.0, "HeadPitch": -10.0}
    assert g.positions_at(1.0, speed=2.0) == {"HeadYaw": 40.0, "HeadPitch": -20.0}  # gesture time 2 s
    assert g.positions_at(3.0) == {"HeadYaw": 20.0, "HeadPitch": -10.0}
    assert g.positions_at(99.0) == {"HeadYaw": 0.0, "HeadPitch": 0.0}
    assert g.positions_at(-1.0) == {"HeadYaw": 0.0, "HeadPitch": 0.0}
    with pytest.raises(GestureError, match="positive"):
        g.duration_at(0.0)


@pytest.mark.parametrize(
    "text,fragment",
    [
        ("<gesture><name>x</name>", "not valid XML"),
        ("<trajectory/>", "root element must be <gesture>"),
        (gesture_xml('<point time="0">0 0</point><point time="1">0 0</point>', name=""), "<name> must be"),
        (gesture_xml('<point time="0">0</point><point time="1">0</point>', joints=""), "no <joints>"),
        (gesture_xml('<point time="0">0 0</point><point time="1">0 0</point>',
                     joints="<joint>HeadYaw</joint><joint>HeadYaw</joint>"), "listed twice"),
        (gesture_xml('<point time="0">0</point><point time="1">0</point>', joints="<joint>Tail</joint>"),
         "unknown joint 'Tail'"),
        (gesture_xml('<point time="0">0 0</point>'), "at least two points"),
        (gesture_xml('<point time="0.5">0 0</point><point time="1">0 0</point>'),
         "first point must be at time 0"),
        (gesture_xml('<point time="0">0 0</point><point time="0">1 1</point>'), "increase"),
        (gesture_xml('<point time="0">0 0</point><point time="x">1 1</point>'), "must be numbers"),
        (gesture_xml('<point time="0">0 0</point><point time="1">1</point>'), "1 values for 2 joints"),
        (gesture_xml('<point time="0">0 0</point><point time="1">90 0</point>'), "HeadYaw 90 deg is outside"),
    ],
)
def test_malformed_gesture_files_are_refused(text: str, fragment: str) -> None:
    with pytest.raises(GestureError) as info:
        parse_gesture_xml(text, "test.xml")
    assert fragment in str(info.value)


def test_gesture_directory_errors(tmp_path: Path) -> None:
    with pytest.raises(GestureError, match="does not exist"):
        GestureLibrary.from_dirs([tmp_path / "missing"])
    with pytest.raises(GestureError, match="cannot read gesture file"):
        load_gesture_file(tmp_path / "none.xml")
    (tmp_path / "a.xml").write_text(gesture_xml('<point time="0">0 0</point><point time="1">5 5</point>',
                                                name="marching"))
    with pytest.raises(GestureError, match="defined twice"):
        GestureLibrary.from_dirs([default_gesture_dir(), tmp_path])


def test_joint_limits_check_and_overrides() -> None:
    limits = JointLimits.default()
    assert limits.check_part("Head", [10, -5]) == [10.0, -5.0]
    assert limits.check_part("left_arm", [90, -60, -30]) == [90.0, -60.0, -30.0]
    with pytest.raises(JointLimitError, match=r"HeadPitch 30 deg is outside its range \[-25, 25\]"):
        limits.check_part("head", [0, 30])
    with pytest.raises(JointLimitError, match="head takes 2 values"):
        limits.check_part("head", [0])
    with pytest.raises(JointLimitError, match="unknown part"):
        canonical_part("tail")
    with pytest.raises(JointLimitError, match="outside"):
        limits.check_joint("HeadYaw", float("nan"))
    narrowed = limits.with_overrides(parse_limit_overrides("HeadYaw:-10:10, HeadPitch:-5:5"))
    with pytest.raises(JointLimitError, match=r"HeadYaw 20 deg is outside its range \[-10, 10\]"):
        narrowed.check_part("head", [20, 0])
    assert limits.limits["HeadYaw"] == DEFAULT_LIMITS["HeadYaw"]  # the default is untouched
    for spec, fragment in [("HeadYaw:1", "Joint:min:max"), ("Knee:0:1", "unknown joint"),
                           ("HeadYaw:a:b", "numbers"), ("HeadYaw:5:1", "min < max")]:
        with pytest.raises(JointLimitError, match=fragment):
            parse_limit_overrides(spec)
    for j in ALL_JOINTS:  # the rest pose is within the limits
        limits.check_joint(j, HOME[j])


def test_emotion_names() -> None:
    assert qt_emotion_name("happy") == "QT/happy"
    assert qt_emotion_name("Happy") == "QT/happy"
    assert qt_emotion_name("lab/custom") == "lab/custom"
    cat = EmotionCatalogue(["QT/happy", "lab/Custom"])
    assert cat.resolve("happy") == "QT/happy"
    assert cat.resolve("QT/HAPPY") == "QT/happy"
    assert cat.resolve("lab/custom") == "lab/Custom"
    assert cat.resolve("sad") is None
