"""The live view's front door: one WebSocket port that accepts both names of the Foxglove WebSocket protocol.

The protocol (https://github.com/foxglove/ws-protocol, ``docs/spec.md``) is negotiated as a WebSocket
subprotocol. Clients of the ws-protocol libraries (the npm ``@foxglove/ws-protocol`` client, Lichtblick,
``foxglove_bridge`` 0.8 and older tools) offer ``foxglove.websocket.v1``; foxglove-sdk, whose server the live view
uses, accepts only ``foxglove.sdk.v1`` (every release from 0.1 to 0.30: its ``handshake.rs`` answers any other
offer with HTTP 400), and the Foxglove app offers that one. The two names stand for the same messages (Foxglove's
own statement when it renamed the subprotocol).

:class:`SubprotocolRelay` listens on the address the user asked for, accepts either name (``foxglove.sdk.v1``
when the client offers both) and relays each connection, frame for frame and unchanged, to the SDK's server
on 127.0.0.1 under ``foxglove.sdk.v1``. It runs an asyncio loop (``websockets``) in one daemon thread.
"""
from __future__ import annotations

import asyncio
import threading

__all__ = ["SDK_SUBPROTOCOL", "WS_PROTOCOL_SUBPROTOCOL", "SUBPROTOCOLS", "SubprotocolRelay"]

#: the subprotocol foxglove-sdk's server speaks
SDK_SUBPROTOCOL = "foxglove.sdk.v1"
#: the subprotocol of the ws-protocol libraries (``FoxgloveClient.SUPPORTED_SUBPROTOCOL`` in @foxglove/ws-protocol)
WS_PROTOCOL_SUBPROTOCOL = "foxglove.websocket.v1"
#: what the relay accepts, the first one offered by the client in this order
SUBPROTOCOLS = (SDK_SUBPROTOCOL, WS_PROTOCOL_SUBPROTOCOL)

_OPEN_TIMEOUT = 10.0  # s: the SDK's server on this machine answers at once; bounds a hang, not a timing check


class SubprotocolRelay:
    """Listen on ``host:port`` (0: a free port, see :attr:`port`) and relay each client to the Foxglove
    WebSocket server at ``ws://127.0.0.1:<upstream_port>``. Raises ``OSError`` if it cannot listen. Call
    :meth:`close` (idempotent) to stop it: its clients are disconnected."""

    def __init__(self, host: str, port: int, upstream_port: int):
        from websockets.asyncio.server import serve
        from websockets.typing import Subprotocol

        self._upstream = f"ws://127.0.0.1:{int(upstream_port)}"
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, name="gyro_sim live relay", daemon=True)
        self._closed = False
        self._thread.start()

        async def start():
            return await serve(self._relay, host, port, subprotocols=[Subprotocol(p) for p in SUBPROTOCOLS],
                               compression=None, max_size=None)

        try:
            self._server = asyncio.run_coroutine_threadsafe(start(), self._loop).result()
        except BaseException:
            self._stop_loop()
            raise
        self.port: int = self._server.sockets[0].getsockname()[1]

    async def _relay(self, client) -> None:
        """One client: open its connection to the SDK's server and copy frames both ways until either closes."""
        from websockets.asyncio.client import connect
        from websockets.exceptions import WebSocketException
        from websockets.typing import Subprotocol

        try:
            upstream = await connect(self._upstream, subprotocols=[Subprotocol(SDK_SUBPROTOCOL)], compression=None,
                                     max_size=None, proxy=None, open_timeout=_OPEN_TIMEOUT)
        except (OSError, asyncio.TimeoutError, WebSocketException) as exc:
            await client.close(1011, f"live view: the Foxglove server is not reachable ({exc})"[:120])
            return
        async with upstream:
            copies = [asyncio.create_task(_copy(client, upstream)), asyncio.create_task(_copy(upstream, client))]
            await asyncio.wait(copies, return_when=asyncio.FIRST_COMPLETED)
            for task in copies:
                task.cancel()
            await asyncio.gather(*copies, return_exceptions=True)
        await client.close()

    def _stop_loop(self) -> None:
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join()
        self._loop.close()
        self._closed = True

    def close(self) -> None:
        """Stop listening, disconnect the clients (close code 1001) and end the relay's thread."""
        if self._closed:
            return

        async def stop():
            self._server.close()
            await self._server.wait_closed()

        asyncio.run_coroutine_threadsafe(stop(), self._loop).result()
        self._stop_loop()


async def _copy(source, sink) -> None:
    """Send every frame ``source`` receives to ``sink`` (text as text, binary as binary) until either closes."""
    from websockets.exceptions import ConnectionClosed

    try:
        async for frame in source:
            await sink.send(frame)
    except ConnectionClosed:
        pass
