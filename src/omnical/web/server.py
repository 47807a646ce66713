"""``omnical monitor``'s server: the page, its WebSocket and the runs' ingest socket (Starlette).

``GET /`` the page, ``/static`` its scripts (uPlot vendored), ``/ws`` a page's frames,
``/ingest`` a run's frames; with a token all but ``/static``, ``/healthz`` need ``?token=``.
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import itertools
import logging
import time
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any

from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import FileResponse, PlainTextResponse, Response
from starlette.routing import Mount, Route, WebSocketRoute
from starlette.staticfiles import StaticFiles
from starlette.websockets import WebSocket, WebSocketDisconnect

from omnical.web.hub import Hub

__all__ = [
    "ACK_BYTES",
    "ACK_WAIT_S",
    "BATCH_BYTES",
    "BATCH_FRAMES",
    "STATIC_DIR",
    "create_app",
    "serve",
]

STATIC_DIR = Path(__file__).with_name("static")
"""The page, its script and style, and the vendored uPlot (package data)."""

_POLICY_VIOLATION = 1008

BATCH_FRAMES = 32
"""Frames that wait for a page go to it in one WebSocket message (a JSON array), up to this
many: one browser task and one parse for a backlog, not one per frame."""

BATCH_BYTES = 64 * 1024
"""...and up to this many characters (but a frame alone may be longer): a late joiner's
history goes in messages a page parses and handles in a few milliseconds each."""

ACK_BYTES = 16 * 1024
"""A page that acknowledges (``/ws?ack=1``: it sends ``ack`` once it is open and once for
every message of this many characters or more it handled, each after its next redraw) gets
its first message once it said it is open, and after such a long message (a late joiner's
history) the next once it handled that one, each up to :data:`ACK_WAIT_S`: sent back to back,
each would wait in the page for all before it, for the page's own start and for the redraws
between them. (The page's ``ACK_CHARS``: the same bound; the messages are ASCII JSON.)"""

ACK_WAIT_S = 0.5
"""How long a message waits for the page's ``ack`` (a stalled page says nothing)."""


def _allowed(token: str | None, given: str | None) -> bool:
    return token is None or (given is not None and hmac.compare_digest(token, given))


def create_app(
    hub: Hub, *, token: str | None = None, tick_s: float = 1.0, batch: int = BATCH_FRAMES
) -> Starlette:
    """The app serving ``hub``; ``token``: required in every URL but the static files',
    ``/healthz`` and ``/favicon.ico``.
    ``batch``: at most this many waiting frames go in one WebSocket message (1: one each)."""
    # a run's key: never reused (``id(ws)`` was, once a closed run's socket was collected, and
    # a device connecting next inherited that run's latched map as its own)
    run_keys = itertools.count(1)

    async def index(request: Request) -> Response:
        if not _allowed(token, request.query_params.get("token")):
            return PlainTextResponse("omnical monitor: a token is required (?token=...)", 403)
        return FileResponse(STATIC_DIR / "index.html", headers={"Cache-Control": "no-store"})

    async def page_socket(ws: WebSocket) -> None:
        if not _allowed(token, ws.query_params.get("token")):
            await ws.close(code=_POLICY_VIOLATION)
            return
        await ws.accept()
        page = hub.attach()
        acks = ws.query_params.get("ack") == "1"

        async def handled(messages: int) -> None:  # the page handled this many long ones
            if acks:
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(page.handled(messages + 1), ACK_WAIT_S)

        async def pump() -> None:
            carried: tuple[str, str] | None = None  # did not fit the last message: the next's
            await handled(0)  # the page is open (its first ack)
            while True:
                stream, payload = carried if carried is not None else await page.get()
                carried = None
                started_s = time.perf_counter()
                texts = [hub.frame_text(stream, payload)]
                size = len(texts[0])
                while len(texts) < batch and (item := page.take()) is not None:
                    text = hub.frame_text(*item)  # what waits goes along: one message
                    if size + len(text) > BATCH_BYTES:
                        carried = item  # stamped again when it leaves
                        break
                    texts.append(text)
                    size += len(text)
                message = texts[0] if len(texts) == 1 else f"[{','.join(texts)}]"
                sending = ws.send_text(message)
                hub.note_busy((time.perf_counter() - started_s) * 1e3)
                await sending
                page.sent += len(texts)
                if len(message) >= ACK_BYTES:  # the next leaves once the page is done with it
                    page.messages += 1
                    await handled(page.messages)

        sender = asyncio.create_task(pump())
        try:
            while True:  # a page says it handled a message, or closes
                message = await ws.receive()
                if message["type"] == "websocket.disconnect":
                    break
                if message.get("text") == "ack":
                    page.ack()
        except WebSocketDisconnect:
            pass
        finally:
            hub.detach(page)
            sender.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await sender

    async def ingest_socket(ws: WebSocket) -> None:
        if not _allowed(token, ws.query_params.get("token")):
            await ws.close(code=_POLICY_VIOLATION)
            return
        if "recording" in hub.latched:  # a replay: a run's frames would turn it into a live view
            refusal = PlainTextResponse("omnical monitor: replaying a recording, not live", 409)
            try:
                await ws.send_denial_response(refusal)
            except RuntimeError:  # a server without the denial extension: a plain refusal
                await ws.close(code=_POLICY_VIOLATION)
            return
        await ws.accept()
        key = next(run_keys)
        try:
            while True:
                text = await ws.receive_text()
                started_s = time.perf_counter()
                try:
                    hub.ingest(key, text)
                    hub.note_busy((time.perf_counter() - started_s) * 1e3)
                except (ValueError, KeyError, TypeError) as err:
                    hub.publish("events", {"t": hub.clock(), "kind": "ingest", "level": "warning",
                                           "text": f"a bad frame from a run: {err}"})  # fmt: skip
        except (WebSocketDisconnect, RuntimeError):
            pass
        finally:
            hub.source_gone(key)

    async def health(_: Request) -> Response:
        return PlainTextResponse("ok")

    async def no_icon(_: Request) -> Response:
        return Response(status_code=204)

    @contextlib.asynccontextmanager
    async def lifespan(_: Starlette) -> AsyncIterator[None]:
        async def ticker() -> None:
            while True:
                await asyncio.sleep(tick_s)
                hub.tick()

        task = asyncio.create_task(ticker())
        try:
            yield
        finally:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task

    routes: list[Any] = [
        Route("/", index),
        Route("/healthz", health),
        Route("/favicon.ico", no_icon),
        WebSocketRoute("/ws", page_socket),
        WebSocketRoute("/ingest", ingest_socket),
        Mount("/static", StaticFiles(directory=STATIC_DIR), name="static"),
    ]
    return Starlette(routes=routes, lifespan=lifespan)


class _DenialIsNoError(logging.Filter):
    """Drops uvicorn's "ASGI callable returned without completing handshake." that its
    websockets-sansio protocol logs after a denial response it did send (0.54; the fix, Kludex/
    uvicorn PR #3138, is open): here the 409 to a run streaming to a replaying monitor."""

    def filter(self, record: logging.LogRecord) -> bool:
        return record.getMessage() != "ASGI callable returned without completing handshake."


_DENIAL_IS_NO_ERROR = _DenialIsNoError()


def _ws_implementation() -> str:
    """uvicorn's sans-I/O ``websockets`` protocol where it has it (the older one is deprecated)."""
    from uvicorn.config import WS_PROTOCOLS

    return "websockets-sansio" if "websockets-sansio" in WS_PROTOCOLS else "websockets"


def serve(
    hub: Hub,
    host: str,
    port: int,
    *,
    token: str | None = None,
    on_ready: Callable[[int], None] | None = None,
    batch: int = BATCH_FRAMES,
) -> None:
    """Serve until Ctrl-C / SIGTERM (uvicorn; the caller's signal handlers stay in charge).

    ``on_ready(port)`` is called once the socket listens (the port actually bound: 0 picks one).
    """
    import socket

    import uvicorn

    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind((host, port))
    sock.listen(128)
    sock.set_inheritable(True)
    config = uvicorn.Config(
        create_app(hub, token=token, batch=batch),
        log_level="warning",
        ws=_ws_implementation(),
        lifespan="on",
        ws_ping_interval=None,
        timeout_graceful_shutdown=1,
    )
    logging.getLogger("uvicorn.error").addFilter(_DENIAL_IS_NO_ERROR)  # after Config's set-up
    server = uvicorn.Server(config)

    async def main() -> None:
        task = asyncio.create_task(server.serve(sockets=[sock]))
        while not server.started and not task.done():
            await asyncio.sleep(0.01)
        if server.started and on_ready is not None:
            on_ready(sock.getsockname()[1])
        try:
            await task
        finally:
            server.should_exit = True

    try:
        asyncio.run(main())
    finally:
        sock.close()
