"""The coach's configuration: the seed's coach.yaml keys plus the new options, validated.

Every key has a default that runs with no hardware; a YAML file (flat, as the seed's, or a
ROS params file section) overrides them. Unknown keys and wrong types are errors, so a
typo cannot silently fall back to a default. :func:`participant_id` turns name and age into
the id every log and event carries (never the name).
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import yaml

from hri_physio_coach.policies import POLICY_NAMES, AdapterOptions


class ConfigError(ValueError):
    """Invalid coach configuration; the message is one line that says what to fix."""


def _strings(*items: str) -> list[str]:
    return list(items)


@dataclass(frozen=True)
class CoachConfig:
    # --- participant (seed keys) ---
    part_name: str = "JohnDoe"
    part_age: float = 28.0
    participant_salt: str = ""  # optional secret mixed into the participant id hash
    address_by_name: bool = False  # speak the name (it then travels on /QtController/input)
    # --- calibration (seed keys calib_time, calib_skip, resting_default) ---
    calib_time: float = 180.0
    calib_skip: bool = False
    resting_default: float = 61.0
    calib_min_samples: int = 30  # fewer valid HR samples: use resting_default
    calib_reminder_period: float = 60.0
    # --- heart-rate zone (fractions of HRR) ---
    zone_low: float = 0.40
    zone_high: float = 0.70
    # --- speed ladder (seed keys) ---
    speed_modifier: list[float] = field(default_factory=lambda: [0.90, 0.95, 1.00, 1.05, 1.10, 1.15])
    audio_suffix: list[str] = field(
        default_factory=lambda: _strings("110", "115", "120", "125", "130", "135"))
    speed_idx: int = 1
    # --- media and gestures (seed keys) ---
    audio_path: str = "./audio/{}.wav"
    video_path: str = "./video/{}.mp4"
    audio_default: str = "default"
    audio_relaxing: str = "relaxing"
    audio_exercise_base: str = "exercise_{}"
    video_default: str = "splash"
    video_relaxing: str = "relaxing"
    video_time: float = 30.0
    gesture_relaxing: str = "base"
    gesture_relaxing_speed: float = 0.5
    # --- timing of the periodic hooks ---
    behaviour_period: float = 20.0
    rule_period: float = 30.0
    hr_report_window: float = 30.0
    # --- heart-rate input and signal gating ---
    hr_timeout: float = 10.0
    hr_valid_min: float = 30.0
    hr_valid_max: float = 230.0
    min_valid_samples: int = 10  # per rule-update buffer
    max_invalid_fraction: float = 0.5  # more invalid or flagged samples: the signal is flagged
    buffer: int = 1000  # seed key: HR buffer length (samples)
    # --- adaptation ---
    policy: str = "threshold"
    seed: int = 0
    adapt_refractory: bool = False
    adapt_refractory_period: float = 60.0
    adapt_conditioning_only: bool = False
    adapt_cooldown_schedule: bool = False
    adapt_warmup_max_speedups: int = -1  # -1: no cap
    # --- routine ---
    routine_file: str = ""  # empty: the packaged exercise routine
    # --- speech and emotions (seed keys) ---
    speech_relaxation: list[str] = field(default_factory=lambda: _strings(
        "Just sit back and take big, slow breaths.",
        "Relax your shoulders and breathe in deeply through your nose.",
    ))
    speech_motivation: list[str] = field(default_factory=lambda: _strings(
        "You are doing great, keep it up!",
        "Nice work, keep going!",
        "Fantastic effort!",
    ))
    speech_faster: list[str] = field(default_factory=lambda: _strings(
        "Let's pick up the pace!",
    ))
    speech_slower: list[str] = field(default_factory=lambda: _strings(
        "Let's slow down a little, don't over-exert yourself.",
    ))
    speech_cooldown: list[str] = field(default_factory=lambda: _strings(
        "Let's slow the pace down as we cool down.",
    ))
    emotion_motivation: list[str] = field(default_factory=lambda: _strings("happy"))
    speech_hr_report: str = "Your average heart rate over the last 30 seconds was {hr:.0f} beats per minute."
    speech_calib_reminder: str = (
        "You're doing great. Don't forget to breathe. Only {minutes_left} {minutes_word} left."
    )
    speech_zone: str = (
        "My calibrations are complete! Thank you for your patience. I measured your resting heart rate "
        "to be {hr_rest:.1f} beats per minute. I will do my best to keep your heart rate between "
        "{zone_low:.1f} and {zone_high:.1f} beats per minute."
    )

    # ------------------------------------------------------------------------------------------
    @property
    def adapter_options(self) -> AdapterOptions:
        cap = self.adapt_warmup_max_speedups
        return AdapterOptions(
            refractory=self.adapt_refractory,
            refractory_period=self.adapt_refractory_period,
            conditioning_only=self.adapt_conditioning_only,
            cooldown_schedule=self.adapt_cooldown_schedule,
            warmup_max_speedups=None if cap < 0 else cap,
        )

    @property
    def participant(self) -> str:
        return participant_id(self.part_name, self.part_age, self.participant_salt)

    def validate(self) -> CoachConfig:
        """Check every cross-field rule; raise :class:`ConfigError` on the first violation."""
        if not (math.isfinite(self.part_age) and 0 < self.part_age <= 120):
            raise ConfigError(f"part_age must be in (0, 120] years, got {self.part_age:g}")
        if not 0.0 <= self.zone_low < self.zone_high <= 1.0:
            raise ConfigError(
                f"zone bounds out of order: need 0 <= zone_low < zone_high <= 1, got {self.zone_low:g}, "
                f"{self.zone_high:g}"
            )
        if self.policy not in POLICY_NAMES:
            raise ConfigError(f"unknown policy {self.policy!r}; choose one of {', '.join(POLICY_NAMES)}")
        if not self.speed_modifier:
            raise ConfigError("empty speed ladder: speed_modifier needs at least one gesture speed")
        if len(self.audio_suffix) != len(self.speed_modifier):
            raise ConfigError(
                f"speed_modifier has {len(self.speed_modifier)} steps but audio_suffix has "
                f"{len(self.audio_suffix)}: one music tempo per gesture speed"
            )
        if any(not (math.isfinite(s) and s > 0) for s in self.speed_modifier):
            raise ConfigError(f"speed_modifier values must be > 0, got {self.speed_modifier}")
        if any(b <= a for a, b in zip(self.speed_modifier, self.speed_modifier[1:], strict=False)):
            raise ConfigError(f"speed_modifier must increase step by step, got {self.speed_modifier}")
        if not 0 <= self.speed_idx < len(self.speed_modifier):
            raise ConfigError(
                f"speed_idx {self.speed_idx} is outside the ladder [0, {len(self.speed_modifier) - 1}]")
        positive = ("calib_time", "calib_reminder_period", "behaviour_period", "rule_period",
                    "hr_report_window", "hr_timeout", "video_time", "gesture_relaxing_speed")
        for key in positive:
            value = getattr(self, key)
            if not (math.isfinite(value) and value > 0):
                raise ConfigError(f"{key} must be > 0, got {value:g}")
        if not (math.isfinite(self.resting_default) and 20 <= self.resting_default <= 150):
            raise ConfigError(f"resting_default must be a plausible resting HR in [20, 150] bpm, "
                              f"got {self.resting_default:g}")
        if not 0 < self.hr_valid_min < self.hr_valid_max:
            raise ConfigError(f"need 0 < hr_valid_min < hr_valid_max, got {self.hr_valid_min:g}, "
                              f"{self.hr_valid_max:g}")
        if not 0.0 <= self.max_invalid_fraction <= 1.0:
            raise ConfigError(f"max_invalid_fraction must be in [0, 1], got {self.max_invalid_fraction:g}")
        for key in ("min_valid_samples", "calib_min_samples"):
            if getattr(self, key) < 1:
                raise ConfigError(f"{key} must be >= 1, got {getattr(self, key)}")
        if self.buffer < self.min_valid_samples:
            raise ConfigError(f"buffer ({self.buffer}) must hold at least min_valid_samples "
                              f"({self.min_valid_samples})")
        if self.adapt_refractory_period < 0:
            raise ConfigError(f"adapt_refractory_period must be >= 0 s, got {self.adapt_refractory_period:g}")
        if self.adapt_warmup_max_speedups < -1:
            raise ConfigError(f"adapt_warmup_max_speedups must be >= 0 (or -1 for no cap), "
                              f"got {self.adapt_warmup_max_speedups}")
        for key in ("speech_motivation", "speech_faster", "speech_slower", "speech_cooldown",
                    "speech_relaxation", "emotion_motivation"):
            if not getattr(self, key):
                raise ConfigError(f"{key} must list at least one entry")
        for key in ("audio_path", "video_path", "audio_exercise_base"):
            if "{}" not in getattr(self, key):
                raise ConfigError(
                    f"{key} must contain '{{}}' where the name goes, got {getattr(self, key)!r}")
        return self

    def replace(self, **changes: Any) -> CoachConfig:
        return config_from_mapping({**self.as_dict(), **changes})

    def as_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


# Types of every key, for checking YAML and ROS parameter values.
_FIELDS = {f.name: f for f in fields(CoachConfig)}
SCALAR_KEYS = tuple(name for name, f in _FIELDS.items() if f.type in ("str", "bool", "int", "float"))


def _coerce(key: str, value: Any, source: str) -> Any:
    kind = _FIELDS[key].type
    bad = ConfigError(f"{source}: {key} must be {kind}, got {value!r}")
    if kind == "bool":
        if not isinstance(value, bool):
            raise bad
        return value
    if kind == "int":
        if isinstance(value, bool) or not isinstance(value, int):
            raise bad
        return value
    if kind == "float":
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise bad
        return float(value)
    if kind == "str":
        if not isinstance(value, str):
            raise bad
        return value
    if kind == "list[float]":
        if not isinstance(value, list) or any(isinstance(v, bool) or not isinstance(v, int | float | str)
                                              for v in value):
            raise ConfigError(f"{source}: {key} must be a list of numbers, got {value!r}")
        try:
            return [float(v) for v in value]
        except ValueError:
            raise ConfigError(f"{source}: {key} must be a list of numbers, got {value!r}") from None
    if kind == "list[str]":
        if not isinstance(value, list) or any(isinstance(v, dict | list) or v is None for v in value):
            raise ConfigError(f"{source}: {key} must be a list of texts, got {value!r}")
        return [str(v) for v in value]
    raise AssertionError(f"unhandled config type {kind}")


def config_from_mapping(values: Mapping[str, Any], source: str = "configuration") -> CoachConfig:
    """A validated :class:`CoachConfig` from a mapping of keys (unknown keys are errors)."""
    unknown = sorted(set(values) - set(_FIELDS))
    if unknown:
        raise ConfigError(f"{source}: unknown key(s) {unknown}")
    coerced = {k: _coerce(k, v, source) for k, v in values.items()}
    return CoachConfig(**coerced).validate()


def read_config_file(path: str | Path, node_name: str = "qt_physio_coach") -> dict[str, Any]:
    """The key/value mapping of a YAML file: flat (the seed's format) or a ROS params file."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"configuration file {p} does not exist")
    try:
        data = yaml.safe_load(p.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        raise ConfigError(f"configuration file {p} is not valid YAML{where}") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigError(f"configuration file {p} must hold key: value pairs")
    for key in (node_name, f"/{node_name}", "/**"):
        section = data.get(key)
        if isinstance(section, dict) and isinstance(section.get("ros__parameters"), dict):
            return dict(section["ros__parameters"])
    return data


def load_config(path: str | Path | None = None, overrides: Mapping[str, Any] | None = None) -> CoachConfig:
    """Defaults < the YAML file < ``overrides``; validated."""
    values: dict[str, Any] = {}
    source = "configuration"
    if path:
        values.update(read_config_file(path))
        source = str(path)
    values.update(overrides or {})
    return config_from_mapping(values, source)


def participant_id(name: str, age: float, salt: str = "") -> str:
    """A stable pseudonymous id from name and age (``P-`` + 10 hex digits of SHA-256).

    The name never appears in logs or events; the same person gets the same id across
    sessions with the same salt. With an empty salt the id can be recomputed by anyone who
    knows name and age, so labs that need more set ``participant_salt``.
    """
    text = f"{salt}\x1f{name.strip().casefold()}\x1f{float(age):g}"
    return "P-" + hashlib.sha256(text.encode("utf-8")).hexdigest()[:10]
