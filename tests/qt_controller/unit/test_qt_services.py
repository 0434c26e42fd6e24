"""The QT service adapter: backend choice, request checking and the std-only JSON request/reply."""

from __future__ import annotations

import sys
import types

import pytest

from qt_controller import qt_services as qs


def test_backend_is_json_without_qt_packages_and_qt_is_refused() -> None:
    assert qs.find_qt_type(qs.GESTURE_PLAY) is None
    assert qs.resolve_backend("auto", qs.GESTURE_PLAY) == "json"
    assert qs.resolve_backend("json", qs.SET_VOLUME) == "json"
    with pytest.raises(ValueError, match=r"needs qt_gesture_controller\.srv"):
        qs.resolve_backend("qt", qs.GESTURE_PLAY)
    with pytest.raises(ValueError, match="must be one of"):
        qs.resolve_backend("ros1", qs.GESTURE_PLAY)


@pytest.mark.parametrize("class_name", ["GesturePlay", "gesture_play"])
def test_qt_types_are_used_when_importable(monkeypatch: pytest.MonkeyPatch, class_name: str) -> None:
    srv = types.ModuleType("qt_gesture_controller.srv")
    marker = type(class_name, (), {})
    setattr(srv, class_name, marker)
    monkeypatch.setitem(sys.modules, "qt_gesture_controller", types.ModuleType("qt_gesture_controller"))
    monkeypatch.setitem(sys.modules, "qt_gesture_controller.srv", srv)
    assert qs.find_qt_type(qs.GESTURE_PLAY) is marker
    assert qs.resolve_backend("auto", qs.GESTURE_PLAY) == "qt"
    assert qs.resolve_backend("json", qs.GESTURE_PLAY) == "json"  # can still be forced


def test_coerce_request_checks_fields_and_types() -> None:
    assert qs.coerce_request(qs.GESTURE_PLAY, {"id": "x", "name": "base", "speed": 1}) == {
        "name": "base", "speed": 1.0}
    assert qs.coerce_request(qs.SET_VOLUME, {"volume": 40.0}) == {"volume": 40}
    assert qs.coerce_request(qs.SET_VELOCITY, {"parts": ["head"], "velocity": 5}) == {
        "parts": ["head"], "velocity": 5}
    for spec, request, fragment in [
        (qs.GESTURE_PLAY, {"name": "base"}, "missing field 'speed'"),
        (qs.GESTURE_PLAY, {"name": 3, "speed": 1.0}, "field 'name' must be str"),
        (qs.GESTURE_PLAY, {"name": "base", "speed": True}, "field 'speed' must be float"),
        (qs.SET_VOLUME, {"volume": 40.5}, "field 'volume' must be int"),
        (qs.SET_VELOCITY, {"parts": [1], "velocity": 5}, "list of strings"),
    ]:
        with pytest.raises(ValueError, match=fragment):
            qs.coerce_request(spec, request)
