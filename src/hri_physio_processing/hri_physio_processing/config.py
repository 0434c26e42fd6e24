"""Configuration of the NeuroKit2 processor: defaults, validation, the seed's YAML keys.

The seed's neurokitProcessor.py read ``name``, ``input``, ``buffer`` (samples per
processing window), ``window`` (samples kept for the next window, i.e. the overlap),
``plot`` and ``verbose``. Those keys are accepted and translated; ours are in seconds.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

from hri_physio_bridge.streamers.factory import split_uri
from hri_physio_processing.features import MODES, QUALITY_METHODS, FeatureSettings

#: Per-mode defaults for options left at 0 ("auto").
MODE_DEFAULTS: dict[str, dict[str, float]] = {
    "ecg": {"flatline_seconds": 2.0, "saturation_fraction": 0.01, "dedup_seconds": 0.2},
    "ppg": {"flatline_seconds": 2.0, "saturation_fraction": 0.01, "dedup_seconds": 0.2},
    # Skin conductance can sit still for seconds and plateau at its peaks.
    "eda": {"flatline_seconds": 10.0, "saturation_fraction": 0.05, "dedup_seconds": 1.0},
}

SEED_KEYS = ("name", "buffer", "window", "plot", "verbose")


class ConfigError(ValueError):
    """A configuration value is unusable; the message names the key and says why."""


@dataclass(frozen=True)
class ProcessorConfig:
    """Every option of neurokit_processor, with a default that runs without hardware."""

    input: str = "ros:/physio/polar_h10/ecg"
    output_prefix: str = ""  # "" = the input topic (ros: inputs only)
    mode: str = "ecg"
    sampling_rate: float = 130.0
    num_channels: int = 1
    channel: int = 0
    window_seconds: float = 60.0
    hop_seconds: float = 5.0
    lsl_output: bool = False
    lsl_prefix: str = ""  # "" = output_prefix
    quality_method: str = "templatematch"
    min_quality: float = 0.5
    min_beats: int = 5
    min_hr: float = 30.0
    max_hr: float = 220.0
    flatline_seconds: float = 0.0  # 0 = mode default
    saturation_fraction: float = 0.0  # 0 = mode default
    rate_tolerance: float = 0.05
    gap_factor: float = 1.5
    min_window_seconds: float = 10.0
    edge_guard_seconds: float = 2.0
    dedup_seconds: float = 0.0  # 0 = mode default
    correct_artifacts: bool = False
    resolve_timeout: float = 10.0
    wait_for_consumers: float = 0.0  # s to wait for a listener on every ROS output (0 = no wait)
    verbose: bool = False

    KEYS: ClassVar[tuple[str, ...]] = ()

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any], source: str = "configuration") -> ProcessorConfig:
        """Build from flat key/value pairs (YAML, ROS parameters); seed keys are translated."""
        data = {str(k).replace("-", "_"): v for k, v in values.items()}
        data = translate_seed_keys(data, source)
        unknown = sorted(set(data) - set(cls.KEYS))
        if unknown:
            raise ConfigError(f"{source}: unknown option(s) {unknown}; known: {sorted(cls.KEYS + SEED_KEYS)}")
        kwargs: dict[str, Any] = {}
        for f in dataclasses.fields(cls):
            if f.name in data:
                kwargs[f.name] = _coerce(f.name, data[f.name], type(getattr(cls(), f.name)), source)
        cfg = cls(**kwargs)
        cfg.validate(source)
        return cfg

    def validate(self, source: str = "configuration") -> None:
        def fail(key: str, why: str) -> None:
            raise ConfigError(f"{source}: {key} {why}")

        try:
            split_uri(self.input)
        except ValueError as exc:
            fail("input", str(exc))
        if self.mode not in MODES:
            fail("mode", f"must be one of {', '.join(MODES)}, got {self.mode!r}")
        if not (math.isfinite(self.sampling_rate) and self.sampling_rate > 0):
            fail("sampling_rate", f"must be > 0 Hz, got {self.sampling_rate}")
        if self.num_channels < 1:
            fail("num_channels", f"must be >= 1, got {self.num_channels}")
        if not 0 <= self.channel < self.num_channels:
            fail("channel", f"must index one of the {self.num_channels} channel(s), got {self.channel}")
        if self.window_samples < 2:
            fail("window_seconds", f"must cover at least 2 samples, got {self.window_seconds} s")
        if not 1 <= self.hop_samples <= self.window_samples:
            fail("hop_seconds", f"must be > 0 and at most window_seconds ({self.window_seconds} s), "
                 f"got {self.hop_seconds} s")
        if self.quality_method not in QUALITY_METHODS:
            fail("quality_method",
                 f"must be one of {', '.join(QUALITY_METHODS)}, got {self.quality_method!r}")
        if not 0 <= self.min_quality <= 1:
            fail("min_quality", f"must be in [0, 1], got {self.min_quality}")
        if self.min_beats < 2:
            fail("min_beats", f"must be >= 2 (a rate needs two beats), got {self.min_beats}")
        if not 0 <= self.min_hr < self.max_hr:
            fail("min_hr/max_hr", f"must satisfy 0 <= min_hr < max_hr, got {self.min_hr}, {self.max_hr}")
        for key in ("flatline_seconds", "saturation_fraction", "dedup_seconds", "edge_guard_seconds",
                    "min_window_seconds", "resolve_timeout", "wait_for_consumers"):
            value = getattr(self, key)
            if not (math.isfinite(value) and value >= 0):
                fail(key, f"must be >= 0, got {value}")
        if self.saturation_fraction > 1:
            fail("saturation_fraction", f"must be at most 1, got {self.saturation_fraction}")
        if not 0 < self.rate_tolerance < 1:
            fail("rate_tolerance", f"must be in (0, 1), got {self.rate_tolerance}")
        if not self.gap_factor > 1:
            fail("gap_factor", f"must be > 1 sample period, got {self.gap_factor}")
        if self.min_window_seconds > self.window_seconds:
            fail("min_window_seconds", f"({self.min_window_seconds} s) cannot exceed window_seconds "
                 f"({self.window_seconds} s)")
        if self.output_prefix and not self.output_prefix.startswith("/"):
            fail("output_prefix",
                 f"must be an absolute ROS name (start with '/'), got {self.output_prefix!r}")

    # -- derived values --------------------------------------------------------
    @property
    def window_samples(self) -> int:
        return round(self.window_seconds * self.sampling_rate)

    @property
    def hop_samples(self) -> int:
        return round(self.hop_seconds * self.sampling_rate)

    def mode_default(self, key: str) -> float:
        value = float(getattr(self, key))
        return value if value > 0 else MODE_DEFAULTS[self.mode][key]

    @property
    def features(self) -> FeatureSettings:
        return FeatureSettings(
            mode=self.mode,
            sampling_rate=self.sampling_rate,
            quality_method=self.quality_method,
            min_quality=self.min_quality,
            min_beats=self.min_beats,
            min_hr=self.min_hr,
            max_hr=self.max_hr,
            flatline_seconds=self.mode_default("flatline_seconds"),
            saturation_fraction=self.mode_default("saturation_fraction"),
            rate_tolerance=self.rate_tolerance,
            correct_artifacts=self.correct_artifacts,
        )

    def resolved_output_prefix(self) -> str:
        if self.output_prefix:
            return self.output_prefix.rstrip("/")
        scheme, _, address = self.input.partition(":")
        if scheme == "ros":
            return address.partition("?")[0].rstrip("/")
        raise ConfigError(
            f"output_prefix is required when the input is not a ROS topic (input is {self.input!r}); "
            f"e.g. output_prefix: /physio/polar_h10/{self.mode}"
        )

    def resolved_lsl_prefix(self) -> str:
        return self.lsl_prefix or self.resolved_output_prefix()


ProcessorConfig.KEYS = tuple(f.name for f in dataclasses.fields(ProcessorConfig))


def _coerce(key: str, value: Any, kind: type, source: str) -> Any:
    try:
        if kind is bool:
            if isinstance(value, bool):
                return value
            text = str(value).strip().lower()
            if text in ("1", "true", "yes", "on"):
                return True
            if text in ("0", "false", "no", "off"):
                return False
            raise ValueError(value)
        if kind is int:
            if isinstance(value, float) and not value.is_integer():
                raise ValueError(value)
            if isinstance(value, bool):
                raise ValueError(value)
            return int(value)
        if kind is float:
            if isinstance(value, bool):
                raise ValueError(value)
            return float(value)
        return str(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{source}: {key} must be {kind.__name__}, got {value!r}") from None


def translate_seed_keys(data: dict[str, Any], source: str) -> dict[str, Any]:
    """Map the seed's keys (samples) onto ours (seconds); refuse contradictory combinations."""
    out = dict(data)
    rate = float(out.get("sampling_rate", ProcessorConfig.sampling_rate))
    if "buffer" in out:
        if "window_seconds" in out:
            raise ConfigError(
                f"{source}: give either buffer (samples, the seed's key) or window_seconds, not both"
            )
        buffer = _coerce("buffer", out.pop("buffer"), int, source)
        keep = _coerce("window", out.pop("window", 0), int, source)
        if "hop_seconds" in out:
            raise ConfigError(f"{source}: give either buffer/window (samples) or hop_seconds, not both")
        if not 0 <= keep < buffer:
            raise ConfigError(
                f"{source}: window (samples kept, {keep}) must be >= 0 and below buffer ({buffer})"
            )
        out["window_seconds"] = buffer / rate
        out["hop_seconds"] = (buffer - keep) / rate
    elif "window" in out:
        raise ConfigError(f"{source}: window (the seed's overlap in samples) needs buffer too")
    if out.pop("plot", False) not in (False, "false", "False", 0):
        raise ConfigError(
            f"{source}: plot is not supported (the node runs headless); record and plot offline"
        )
    name = out.pop("name", None)
    if name is not None and "lsl_prefix" not in out:
        out["lsl_prefix"] = "/" + str(name).strip("/")
    inp = out.get("input")
    if isinstance(inp, str) and ":" not in inp:
        out["input"] = "lsl:" + inp  # the seed's input was an LSL stream name
    return out
