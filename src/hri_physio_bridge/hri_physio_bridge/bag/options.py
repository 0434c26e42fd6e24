"""The recorder's and the replayer's options, declared once (flags, --conf keys, ROS parameters).

No rclpy here: both configurations are checked before ROS starts. The positional arguments
(topics to record, the bag to play) and the modes that need no ROS (``--repair``, ``--info``)
are the node modules' own command-line arguments, not options.
"""

from __future__ import annotations

import re
from datetime import datetime
from typing import Literal

from pydantic import field_validator

from hri_physio_bridge.bag.errors import BagError
from hri_physio_bridge.bag.topic_selection import bag_name, parse_remaps
from hri_physio_bridge.bag.writer import DEFAULT_CHUNK_SIZE, DEFAULT_FLUSH_PERIOD, DEFAULT_FSYNC_PERIOD
from hri_physio_bridge.config import NodeConfig, option


def _check_regex(value: str) -> str:
    if value:
        try:
            re.compile(value)
        except re.error as exc:
            raise ValueError(f"{value!r} is not a valid regular expression: {exc}") from None
    return value


class RecorderConfig(NodeConfig):
    """What to record, where, and how often the bag reaches the disk."""

    regex: str = option("", "also record topics whose full name matches this regular expression")
    exclude: str = option("", "never record topics whose full name matches this regular expression")
    include_hidden: bool = option(False, "record hidden topics (a name part starting with '_')", switch=True)
    output: str = option("", "bag directory to create, never overwritten "
                         "(default: OUTPUT_DIR/SESSION_ID_<date-time>)")
    output_dir: str = option("bags", "where bags are created when no output is given")
    session_id: str = option("session", "pseudonymous session id in the bag name and metadata")
    discovery_period: float = option(0.5, "time between looks at the ROS graph for new topics",
                                     unit="s", gt=0)
    status_period: float = option(5.0, "time between progress reports", unit="s", gt=0)
    chunk_size: int = option(DEFAULT_CHUNK_SIZE, "MCAP chunk size before compression", unit="bytes", ge=1)
    flush_period: float = option(DEFAULT_FLUSH_PERIOD, "close and write out a chunk at least this often: "
                                 "the most a crash loses", unit="s", gt=0)
    fsync_period: float = option(DEFAULT_FSYNC_PERIOD, "fsync at most this often (0 = only at the end)",
                                 unit="s", ge=0)
    compression: Literal["zstd", "none"] = option("zstd", "chunk compression")
    qos_depth: int = option(10000, "subscription queue depth; must hold what a topic sends in one "
                            "poll period", unit="messages", ge=1)
    drain_timeout: float = option(10.0, "at a stop, the most time spent writing what the subscriptions "
                                  "already hold (up to qos_depth per topic); a topic still delivering after "
                                  "that is left, with an error line", unit="s", gt=0)
    poll_period: float = option(0.1, "time between takes of queued messages while they flow; receive "
                                "stamps come from the middleware, so this only delays the disk",
                                unit="s", gt=0)

    _regex = field_validator("regex", "exclude")(_check_regex)

    @field_validator("session_id")
    @classmethod
    def _session(cls, value: str) -> str:
        try:
            bag_name(value, datetime(2000, 1, 1))  # the name's rules, any date
        except BagError as exc:
            raise ValueError(str(exc)) from None
        return value


class ReplayerConfig(NodeConfig):
    """How to play a bag back: speed, topics, remapping, /clock."""

    rate: float = option(1.0, "speed factor (0 = as fast as possible, order kept)", ge=0)
    loop: bool = option(False, "start again at the end, until stopped", switch=True)
    topics: list[str] = option([], "play only these topics")
    regex: str = option("", "play only topics whose full name matches (with topics: either)")
    exclude: str = option("", "never play topics whose full name matches")
    remap: list[str] = option([], "publish topic FROM as TO, written FROM:=TO")
    start_offset: float = option(0.0, "skip the first seconds of the bag", unit="s", ge=0)
    clock: bool = option(False, "publish /clock from the bag's time (for use_sim_time)", switch=True)
    clock_step: float = option(0.01, "bag time between /clock messages; keep it <= the shortest timer "
                               "period of the nodes on sim time", unit="s", gt=0)
    skip_unknown: bool = option(False, "leave out topics whose message type is not installed "
                                "(default: refuse to play)", switch=True)
    wait_for_subscribers: float = option(0.0, "wait up to this long for a subscriber on every played "
                                         "topic before starting", unit="s", ge=0)
    delay: float = option(0.0, "sleep this long before playing", unit="s", ge=0)
    qos_depth: int = option(1000, "publisher queue depth", unit="messages", ge=1)

    _regex = field_validator("regex", "exclude")(_check_regex)

    @field_validator("remap")
    @classmethod
    def _remaps(cls, value: list[str]) -> list[str]:
        try:
            parse_remaps(value)
        except BagError as exc:
            raise ValueError(str(exc)) from None
        return value

    @field_validator("topics")
    @classmethod
    def _topics(cls, value: list[str]) -> list[str]:
        bad = [t for t in value if not t.startswith("/")]
        if bad:
            raise ValueError(f"topics must be absolute (start with '/'): {', '.join(bad)}")
        return value

    def remaps(self) -> dict[str, str]:
        return parse_remaps(self.remap)

