"""The coach's configuration: the seed's coach.yaml keys plus our own, each declared once.

:class:`CoachConfig` is a :class:`~hri_physio_bridge.config.NodeConfig`: every key has its type,
a default that runs with no hardware, its help text, unit and bounds on the field, and the
rules between keys (zone order, ladder, templates) in one validator. A YAML file (flat, as the
seed's, or a ROS params file section) overrides the defaults; unknown keys and wrong types are
:class:`~hri_physio_bridge.config.ConfigError` (one line naming the key), so a typo cannot
silently fall back to a default. :class:`CoachNodeConfig` adds the node's topics and timing.
:func:`participant_id` turns name and age into the id every log and event carries (never the name).
"""

from __future__ import annotations

import hashlib
import itertools
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar, Literal

from pydantic import model_validator

from hri_physio_bridge import topics
from hri_physio_bridge.config import ConfigError, NodeConfig, option
from hri_physio_coach.policies.adapter import AdapterOptions
from hri_physio_coach.policies.registry import POLICY_NAMES
from hri_physio_coach.zones import tanaka_hr_max
from qt_controller.commands import GESTURE_SPEED_RANGE

__all__ = ["COACH_NODE", "CoachConfig", "CoachNodeConfig", "ConfigError", "load_config", "participant_id"]

#: The coach node's name: the section of a ROS params file that holds its options.
COACH_NODE = "qt_physio_coach"
PolicyName = Literal[POLICY_NAMES]  # type: ignore[valid-type]
_SPEECH_LISTS = ("speech_relaxation", "speech_motivation", "speech_faster", "speech_slower",
                 "speech_cooldown", "emotion_motivation", "emotion_calibration", "speech_activity_switch")
_NAME_TEMPLATES = ("audio_path", "video_path", "audio_exercise_base")


class CoachConfig(NodeConfig):
    """The exercise session's options (``config/coach.yaml`` lists every one with its default)."""

    SEED_KEYS: ClassVar[tuple[str, ...]] = (
        "part_name", "part_age", "calib_time", "calib_skip", "resting_default", "speed_idx",
        "speed_modifier", "audio_suffix", "audio_path", "video_path", "audio_default", "audio_relaxing",
        "audio_exercise_base", "video_default", "video_relaxing", "video_time", "gesture_relaxing",
        "gesture_relaxing_speed", "speech_relaxation", "speech_motivation", "speech_faster",
        "speech_slower", "speech_cooldown", "speech_hr_report", "speech_calib_reminder", "speech_zone",
        "emotion_motivation", "buffer",
    )

    # --- participant ---------------------------------------------------------------------------
    part_name: str = option("JohnDoe", "participant name: only its hash (with age and salt) is logged")
    part_age: float = option(28.0, "participant age, for HR_max = 208 - 0.7 age", unit="years", gt=0, le=120)
    participant_salt: str = option("", "secret mixed into the participant id hash")
    address_by_name: bool = option(False, "the robot says the name (it then travels on the robot's "
                                   "command topic)")
    # --- calibration ---------------------------------------------------------------------------
    calib_time: float = option(180.0, "seated calibration of HR_rest", unit="s", gt=0)
    calib_settle: float = option(15.0, "first seconds of the calibration left out of HR_rest (the "
                                 "participant has just sat down; at most a quarter of the phase)",
                                 unit="s", ge=0)
    calib_skip: bool = option(False, "skip the calibration phase and use resting_default")
    resting_default: float = option(61.0, "HR_rest when calibration is skipped or has too few samples",
                                    unit="bpm", ge=20, le=150)
    calib_min_samples: int = option(30, "fewer valid HR samples in calibration: use resting_default",
                                    unit="samples", ge=1)
    calib_reminder_period: float = option(60.0, "time between 'breathe / time left' reminders",
                                          unit="s", gt=0)
    calib_face_period: float = option(45.0, "time between encouraging faces during the calibration",
                                      unit="s", gt=0)
    emotion_calibration: list[str] = option(["showing_smile", "happy_blinking", "happy"],
                                            "encouraging faces of the calibration, in turn", min_length=1)
    # --- heart-rate zone -----------------------------------------------------------------------
    zone_low: float = option(0.40, "lower zone bound as a fraction of the heart-rate reserve (HRR40)",
                             ge=0, le=1)
    zone_high: float = option(0.70, "upper zone bound as a fraction of the heart-rate reserve (HRR70)",
                              ge=0, le=1)
    # --- speed ladder --------------------------------------------------------------------------
    speed_modifier: list[float] = option([0.90, 0.95, 1.00, 1.05, 1.10, 1.15],
                                         "gesture speed of each ladder step, increasing", min_length=1)
    audio_suffix: list[str] = option(["110", "115", "120", "125", "130", "135"],
                                     "music tempo suffix of each ladder step (one per gesture speed)",
                                     min_length=1)
    speed_idx: int = option(1, "ladder step at the start", ge=0)
    # --- media and gestures --------------------------------------------------------------------
    audio_path: str = option("{}", "audio request of a name ('{}' = the name; the default passes "
                             "the audio streamer's built-in sources, e.g. './audio/{}.wav' for files)")
    video_path: str = option("{}", "video request of a name ('{}' = the name; the default passes "
                             "the video streamer's built-in screens, e.g. './video/{}.mp4' for files)")
    audio_default: str = option("default", "seed key, loaded but not used by the coach yet")
    audio_relaxing: str = option("relaxing", "audio of the calibration and the end")
    audio_exercise_base: str = option("beat:{}", "exercise music name ('{}' = the ladder's suffix; "
                                      "beat:<bpm> is the audio streamer's built-in beat)")
    video_default: str = option("splash", "the splash screen video")
    video_relaxing: str = option("relaxing", "video of the calibration")
    video_time: float = option(30.0, "reference video shown before the splash screen", unit="s", gt=0)
    gesture_relaxing: str = option("base", "gesture of the calibration")
    gesture_relaxing_speed: float = option(0.5, "speed of the calibration gesture",
                                           ge=GESTURE_SPEED_RANGE[0], le=GESTURE_SPEED_RANGE[1])
    gesture_repeat: bool = option(True, "repeat an exercise activity's gesture (at the current speed) for "
                                  "as long as the activity lasts, as the robot leads the participant (the "
                                  "gestures qt_controller ships; another is played once)")
    # --- periodic hooks ------------------------------------------------------------------------
    behaviour_period: float = option(20.0, "time between random behaviours", unit="s", gt=0)
    rule_period: float = option(30.0, "time between rule updates (a rule update wins over a behaviour "
                                "due at the same instant)", unit="s", gt=0)
    hr_report_window: float = option(30.0, "window of the spoken average heart rate", unit="s", gt=0)
    # --- heart-rate input and signal gating ----------------------------------------------------
    hr_timeout: float = option(10.0, "time without HR before adaptation pauses (the routine goes on)",
                               unit="s", gt=0)
    reply_timeout: float = option(30.0, "a robot command with no reply from qt_controller after this long "
                                  "(session time; a restarting controller, say) is recorded as a "
                                  "command_unanswered event", unit="s", gt=0)
    hr_wait: float = option(3.0, "longest the calibration or a rule update waits for the heart rate taken "
                            "before it to arrive (at its activity's end the routine waits with it; 0: "
                            "decide on what has arrived)",
                            unit="s", ge=0)
    hr_valid_min: float = option(30.0, "lowest plausible heart rate", unit="bpm", gt=0)
    hr_valid_max: float = option(230.0, "highest plausible heart rate", unit="bpm", gt=0)
    min_valid_samples: int = option(10, "valid HR samples a rule update needs", unit="samples", ge=1)
    max_invalid_fraction: float = option(0.5, "more invalid or flagged samples than this: signal flagged, "
                                         "no update", ge=0, le=1)
    buffer: int = option(1000, "HR buffer length", unit="samples", ge=1)
    # --- adaptation ----------------------------------------------------------------------------
    policy: PolicyName = option("threshold", "adaptation policy: threshold (Algorithm 1), fuzzy "
                                "(Algorithm 2), static (control condition), predictive (acts on the "
                                "predicted steady-state HR, chooses activity and pace), adaptive (identifies "
                                "the "
                                "person online, banded predictions, overshoot guard, alternates two settings "
                                "across a gap)")
    seed: int = option(0, "seed of the fuzzy policy's draws and of the random behaviours", ge=0)
    adapt_refractory: bool = option(False, "no adaptation within adapt_refractory_period of the last one")
    adapt_refractory_period: float = option(60.0, "the refractory period", unit="s", ge=0)
    adapt_conditioning_only: bool = option(False, "adapt in the conditioning phase only")
    adapt_cooldown_schedule: bool = option(False, "the ladder falls linearly to the bottom through the "
                                           "cool-down")
    adapt_warmup_max_speedups: int = option(-1, "most speed-ups in the warm-up (-1: no cap)", ge=-1)
    # --- routine -------------------------------------------------------------------------------
    routine_file: str = option("", "routine YAML file (empty: the packaged exercise routine)")
    # --- speech and emotions -------------------------------------------------------------------
    speech_relaxation: list[str] = option([
        "Just sit back and take big, slow breaths.",
        "Relax your shoulders and breathe in deeply through your nose.",
    ], "seed key, loaded but not used by the coach yet", min_length=1)
    speech_motivation: list[str] = option([
        "You are doing great, keep it up!", "Nice work, keep going!", "Fantastic effort!",
    ], "encouragements (random behaviour, pace kept)", min_length=1)
    speech_faster: list[str] = option(["Let's pick up the pace!"], "said on a speed-up", min_length=1)
    speech_slower: list[str] = option(["Let's slow down a little, don't over-exert yourself."],
                                      "said on a slow-down", min_length=1)
    speech_cooldown: list[str] = option(["Let's slow the pace down as we cool down."],
                                        "said on a scheduled cool-down slow-down", min_length=1)
    emotion_motivation: list[str] = option(["happy"], "faces of the random behaviour", min_length=1)
    speech_hr_report: str = option(
        "Your average heart rate over the last 30 seconds was {hr:.0f} beats per minute.",
        "the heart-rate report ({hr} = mean of hr_report_window)")
    speech_calib_reminder: str = option(
        "You're doing great. Don't forget to breathe. Only {minutes_left} {minutes_word} left.",
        "the calibration reminder")
    speech_zone: str = option(
        "My calibrations are complete! Thank you for your patience. I measured your resting heart rate "
        "to be {hr_rest:.1f} beats per minute. I will do my best to keep your heart rate between "
        "{zone_low:.1f} and {zone_high:.1f} beats per minute.",
        "the zone announcement after calibration")
    speech_activity_switch: list[str] = option([
        "Let's switch to {label} now, follow my lead!",
    ], "said when a policy that picks activities runs {label} in place of the routine's {routine_label}",
        min_length=1)
    speech_out_of_reach_below: str = option(
        "You are working as hard as this routine goes, and that is fine: keep going at this pace.",
        "said once when heart rate stays below the zone with every control at its limit")
    speech_out_of_reach_above: str = option(
        "This is the gentlest pace of the routine: keep going as comfortably as you can.",
        "said once when heart rate stays above the zone with every control at its lowest")

    @model_validator(mode="after")
    def _rules_between_keys(self) -> CoachConfig:
        if not self.zone_low < self.zone_high:
            raise ValueError(f"zone bounds out of order: need zone_low < zone_high, got {self.zone_low:g}, "
                             f"{self.zone_high:g}")
        speeds = self.speed_modifier
        if len(self.audio_suffix) != len(speeds):
            raise ValueError(f"speed_modifier has {len(speeds)} steps but audio_suffix has "
                             f"{len(self.audio_suffix)}: one music tempo per gesture speed")
        low, high = GESTURE_SPEED_RANGE
        if any(not (math.isfinite(s) and low <= s <= high) for s in speeds):
            raise ValueError(f"speed_modifier values must be gesture speeds in [{low:g}, {high:g}], "
                             f"got {speeds}")
        if any(b <= a for a, b in itertools.pairwise(speeds)):
            raise ValueError(f"speed_modifier must increase step by step, got {speeds}")
        if self.speed_idx >= len(speeds):
            raise ValueError(f"speed_idx {self.speed_idx} is outside the ladder [0, {len(speeds) - 1}]")
        hr_max = tanaka_hr_max(self.part_age)
        if not self.resting_default < hr_max:
            raise ValueError(f"resting_default {self.resting_default:g} bpm must be below the participant's "
                             f"HR_max {hr_max:.1f} bpm (208 - 0.7 x part_age {self.part_age:g})")
        if not self.hr_valid_min < self.hr_valid_max:
            raise ValueError(f"need hr_valid_min < hr_valid_max, got {self.hr_valid_min:g}, "
                             f"{self.hr_valid_max:g}")
        if self.buffer < self.min_valid_samples:
            raise ValueError(f"buffer ({self.buffer}) must hold at least min_valid_samples "
                             f"({self.min_valid_samples})")
        for key in _SPEECH_LISTS:
            if any(not entry.strip() for entry in getattr(self, key)):
                raise ValueError(f"{key}: every entry must be a non-empty text")
        for key in _NAME_TEMPLATES:
            if "{}" not in getattr(self, key):
                raise ValueError(f"{key} must contain '{{}}' where the name goes, got {getattr(self, key)!r}")
        return self

    # ------------------------------------------------------------------------------------------
    @property
    def adapter_options(self) -> AdapterOptions:
        cap = self.adapt_warmup_max_speedups
        return AdapterOptions(
            refractory_period=self.adapt_refractory_period if self.adapt_refractory else None,
            conditioning_only=self.adapt_conditioning_only,
            cooldown_schedule=self.adapt_cooldown_schedule,
            warmup_max_speedups=None if cap < 0 else cap,
        )

    @property
    def participant(self) -> str:
        return participant_id(self.part_name, self.part_age, self.participant_salt)

    def music_requests(self) -> list[str]:
        """The audio requests of the ladder's music (one per step) and of the relaxing music: what an
        audio streamer can prepare before the session, so no change of tempo waits for its track."""
        names = [self.audio_exercise_base.format(suffix) for suffix in self.audio_suffix]
        return list(dict.fromkeys(self.audio_path.format(name) for name in [*names, self.audio_relaxing]))


class CoachNodeConfig(CoachConfig):
    """``qt_physio_coach``'s options: the session's, plus its topics and timing."""

    hr_topic: str = option(topics.POLAR_H10_HR, "heart-rate frames [t, bpm] (std_msgs/Float64MultiArray)",
                           min_length=1)
    command_topic: str = option(topics.QT_COMMANDS, "robot command lines out (qt_controller's input)",
                                min_length=1)
    reply_topic: str = option(topics.QT_REPLIES, "qt_controller's JSON replies in", min_length=1)
    events_topic: str = option(topics.COACH_EVENTS, "one JSON object per decision out", min_length=1)
    state_topic: str = option(topics.COACH_STATE, "the latest state (latched) out", min_length=1)
    control_topic: str = option(topics.COACH_CONTROL, "control words in: start, stop", min_length=1)
    interactive: bool = option(False, "wait for 'start' on stdin or the control topic before starting",
                               switch=True)
    tick_period: float = option(0.1, "how often the session is advanced on ROS time (under sim time "
                                "keep each /clock step <= it)", unit="s", gt=0)


def load_config(path: str | Path | None = None, overrides: Mapping[str, Any] | None = None,
                config_cls: type[CoachConfig] = CoachConfig) -> CoachConfig:
    """Defaults < the YAML file (flat or the coach's ROS params section) < ``overrides``; validated.

    Raises :class:`ConfigError` (one line naming the key) on anything invalid.
    """
    if path:
        return config_cls.from_file(path, COACH_NODE, overrides)
    return config_cls.from_mapping(dict(overrides or {}), "configuration")


def participant_id(name: str, age: float, salt: str = "") -> str:
    """A stable pseudonymous id from name and age (``P-`` + 10 hex digits of SHA-256).

    The name never appears in logs or events; the same person gets the same id across
    sessions with the same salt. With an empty salt the id can be recomputed by anyone who
    knows name and age, so labs that need more set ``participant_salt``.
    """
    text = f"{salt}\x1f{name.strip().casefold()}\x1f{float(age):g}"
    return "P-" + hashlib.sha256(text.encode("utf-8")).hexdigest()[:10]
