"""Requests on the PMD control point, one at a time, each matched to its answer.

The device answers a request with one or more indications (``more`` set on all but the last);
:class:`ControlPointChannel` sends one request at a time (a lock: a watchdog restart and a
device-stop restart may ask at once), collects its answer, and turns refusals into the
streamer's errors: a request this device can never accept (:class:`UnsupportedError`, not
retried), INVALID_MTU (:class:`MtuRefusedError`, retried on a new connection), anything else
(:class:`~hri_physio_bridge.polar.control_point.ControlPointRefused`, retried).

An error answer that names no op (``F0 00 01 0A``) answers the pending request for the same
measurement type (:func:`~hri_physio_bridge.polar.control_point.answers`); anything else that
does not answer the pending request is counted in :attr:`ControlPointChannel.unexpected`.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable

from hri_physio_bridge.polar import control_point as cp
from hri_physio_bridge.polar.ble import BleClient, ConnectionLostError
from hri_physio_bridge.polar.gatt import PMD_CONTROL_POINT
from hri_physio_bridge.polar.mtu import refused_mtu_message
from hri_physio_bridge.polar.protocol import PolarProtocolError

#: Control point statuses that a retry will not fix (the request itself is wrong for this device).
UNSUPPORTED_STATUSES = {
    cp.Status.INVALID_OP_CODE,
    cp.Status.INVALID_MEASUREMENT_TYPE,
    cp.Status.NOT_SUPPORTED,
    cp.Status.INVALID_LENGTH,
    cp.Status.INVALID_PARAMETER,
    cp.Status.INVALID_RESOLUTION,
    cp.Status.INVALID_SAMPLE_RATE,
    cp.Status.INVALID_RANGE,
    cp.Status.INVALID_NUMBER_OF_CHANNELS,
}


class UnsupportedError(RuntimeError):
    """The device does not offer a requested stream or setting (not retried)."""


class MtuRefusedError(ConnectionLostError):
    """The device answered INVALID_MTU: the link's MTU is too small (retried on a new connection)."""


def describe_request(payload: bytes) -> str:
    """``start ECG at sample rate 130, resolution 14`` for a request's bytes."""
    text = cp.request_name(payload[0], payload[1])
    try:
        settings = cp.decode_settings(payload[2:])
    except PolarProtocolError:
        settings = {}
    if settings:
        text += " at " + ", ".join(f"{k.name.lower().replace('_', ' ')} {v[0]}" for k, v in settings.items())
    return text


class ControlPointChannel:
    """The session's side of the control point: requests out, answers in."""

    def __init__(
        self,
        timeout: float,
        *,
        record: Callable[[str, str, bytes], None],
        on_stop: Callable[[cp.StopIndication], None],
        warn: Callable[[str], None],
    ) -> None:
        self.timeout = timeout
        self.mtu: int | None = None  # the link's, for the INVALID_MTU message
        self.unexpected = 0
        self.mtu_refusals = 0
        self._record = record
        self._on_stop = on_stop
        self._warn = warn
        self._lock = asyncio.Lock()
        self._pending: tuple[int, int, asyncio.Future[cp.ControlPointResponse], bytearray] | None = None

    def reset(self) -> None:
        """A new connection: nothing is pending."""
        self._pending = None
        self._lock = asyncio.Lock()

    async def request(
        self, client: BleClient, payload: bytes, allow_refusal: bool = False
    ) -> cp.ControlPointResponse:
        """Send ``payload`` and wait for its whole answer; refusals raise (or, allowed, are logged)."""
        async with self._lock:
            response = await self._exchange(client, payload)
        op, m = payload[0], payload[1]
        accepted = response.ok or (
            op in (cp.OpCode.START, cp.OpCode.STOP) and response.status == cp.Status.ALREADY_IN_STATE
        )
        if accepted:
            return response
        refused = cp.ControlPointRefused(op, m, response.status)
        if allow_refusal:
            self._warn(str(refused))
        elif response.status == cp.Status.INVALID_MTU:
            self.mtu_refusals += 1
            raise MtuRefusedError(refused_mtu_message(describe_request(payload), self.mtu))
        elif response.status in UNSUPPORTED_STATUSES:
            raise UnsupportedError(str(refused))
        else:
            raise refused
        return response

    async def _exchange(self, client: BleClient, payload: bytes) -> cp.ControlPointResponse:
        future: asyncio.Future[cp.ControlPointResponse] = asyncio.get_running_loop().create_future()
        self._pending = (payload[0], payload[1], future, bytearray())
        try:
            self._record("write", PMD_CONTROL_POINT, payload)
            await client.write_gatt_char(PMD_CONTROL_POINT, payload, response=True)
            try:
                return await asyncio.wait_for(future, self.timeout)
            except TimeoutError:
                raise ConnectionLostError(
                    f"the device did not answer '{payload.hex(' ')}' within {self.timeout:g} s"
                ) from None
        finally:
            self._pending = None

    def on_indication(self, data: bytes) -> None:
        """A control point indication: part of the pending answer, a device stop, or unexpected."""
        self._record("notify", PMD_CONTROL_POINT, data)
        try:
            message = cp.decode_control_point(data)
        except PolarProtocolError as exc:
            self._warn(f"unreadable control point indication: {exc}")
            return
        if isinstance(message, cp.StopIndication):
            self._on_stop(message)
            return
        pending = self._pending
        if pending is None or not cp.answers(message, pending[0], pending[1]):
            self.unexpected += 1
            return
        op, m, future, params = pending
        params += message.params
        if message.more:
            return
        if not future.done():
            future.set_result(cp.ControlPointResponse(op, m, message.status, False, bytes(params)))
