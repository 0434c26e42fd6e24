"""A Foxglove WebSocket client for tests (aiohttp underneath).

foxglove-sdk 0.30 accepts the subprotocol ``foxglove.sdk.v1`` (and refuses a handshake that offers
only the earlier ``foxglove.websocket.v1``); the messages are those of the ws-protocol's v1.

The server sends JSON text frames (``serverInfo``, ``advertise`` with each channel's id, topic,
encoding, schema name and schema) and binary message data: opcode 0x01, uint32 subscription id,
uint64 log time (ns), then the payload, all little-endian. The client subscribes with
``{"op": "subscribe", "subscriptions": [{"id": <its id>, "channelId": <channel>}]}``.
"""

from __future__ import annotations

import asyncio
import json
import struct
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

#: Offered in this order; the server picks one.
SUBPROTOCOLS = ("foxglove.sdk.v1", "foxglove.websocket.v1")
MESSAGE_DATA = 0x01
_HEADER = struct.Struct("<BIQ")


@dataclass
class Received:
    """What a client saw: the server's info, the channels by topic, and messages by topic."""

    protocol: str | None = None  # the subprotocol the server chose
    server_info: dict[str, Any] | None = None
    channels: dict[str, dict[str, Any]] = field(default_factory=dict)
    messages: dict[str, list[tuple[int, bytes]]] = field(default_factory=dict)  # (log time ns, payload)


def parse_message_data(frame: bytes) -> tuple[int, int, bytes]:
    """A binary message-data frame -> (subscription id, log time in ns, payload)."""
    op, subscription, log_time = _HEADER.unpack_from(frame)
    assert op == MESSAGE_DATA, f"binary opcode {op}, not message data"
    return subscription, log_time, frame[_HEADER.size:]


async def _watch(url: str, topics: dict[str, int], timeout: float,
                 on_subscribed: Callable[[], None] | None) -> Received:
    import aiohttp

    seen = Received()
    deadline = time.monotonic() + timeout
    subscribed: dict[int, str] = {}
    async with aiohttp.ClientSession() as session, session.ws_connect(url, protocols=SUBPROTOCOLS) as ws:
        assert ws.protocol in SUBPROTOCOLS, ws.protocol
        seen.protocol = ws.protocol
        while True:
            done = all(len(seen.messages.get(t, [])) >= n for t, n in topics.items())
            if done:
                return seen
            left = deadline - time.monotonic()
            if left <= 0:
                counts = {t: len(seen.messages.get(t, [])) for t in topics}
                raise AssertionError(f"timed out after {timeout:g} s: messages {counts} of {topics}; "
                                     f"channels advertised: {sorted(seen.channels)}")
            try:
                msg = await ws.receive(timeout=left)
            except TimeoutError:
                continue
            if msg.type == aiohttp.WSMsgType.TEXT:
                data = json.loads(msg.data)
                if data.get("op") == "serverInfo":
                    seen.server_info = data
                elif data.get("op") == "advertise":
                    for channel in data["channels"]:
                        seen.channels[channel["topic"]] = channel
                    wanted = [seen.channels[t] for t in topics if t in seen.channels
                              and seen.channels[t]["id"] not in subscribed]
                    if wanted:
                        subs = [{"id": 100 + c["id"], "channelId": c["id"]} for c in wanted]
                        await ws.send_str(json.dumps({"op": "subscribe", "subscriptions": subs}))
                        subscribed.update({c["id"]: c["topic"] for c in wanted})
                        if on_subscribed is not None and set(subscribed.values()) >= set(topics):
                            on_subscribed()
            elif msg.type == aiohttp.WSMsgType.BINARY:
                subscription, log_time, payload = parse_message_data(msg.data)
                topic = subscribed[subscription - 100]
                seen.messages.setdefault(topic, []).append((log_time, payload))
            elif msg.type in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED, aiohttp.WSMsgType.ERROR):
                raise AssertionError(f"the server closed the connection: {msg}")


def watch(url: str, topics: dict[str, int], timeout: float = 60.0,
          on_subscribed: Callable[[], None] | None = None) -> Received:
    """Connect, subscribe to ``topics`` once advertised, and return once each has sent its count of
    messages (``{topic: count}``); ``on_subscribed`` is called once every one is subscribed to."""
    return asyncio.run(_watch(url, topics, timeout, on_subscribed))


def check_against_schema(value: Any, schema: dict[str, Any], where: str = "message") -> None:
    """Assert that ``value`` fits ``schema`` (the JSON Schema keywords the live view uses: type, with a
    list of types too, properties, required, items)."""
    kinds = schema.get("type")
    if kinds is not None:
        kinds = [kinds] if isinstance(kinds, str) else kinds
        python = {"object": dict, "array": list, "string": str, "boolean": bool, "null": type(None),
                  "integer": int, "number": (int, float)}
        fits = [k for k in kinds if isinstance(value, python[k])
                and not (k in ("integer", "number") and isinstance(value, bool))]
        assert fits, f"{where}: {value!r} is not of type {kinds}"
    if isinstance(value, dict):
        for name in schema.get("required", []):
            assert name in value, f"{where}: required field {name!r} missing"
        for name, sub in schema.get("properties", {}).items():
            if name in value:
                check_against_schema(value[name], sub, f"{where}.{name}")
    if isinstance(value, list) and "items" in schema:
        for i, item in enumerate(value):
            check_against_schema(item, schema["items"], f"{where}[{i}]")
