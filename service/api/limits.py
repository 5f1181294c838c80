"""Refuse oversize request bodies with 413 before they are buffered."""

from __future__ import annotations

import json

from starlette.exceptions import HTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

#: Bytes a request body may hold beside a depth image of ``VGN_MAX_FRAME_BYTES``: the frame's
#: meta JSON and the multipart headers. ``VGN_MAX_FRAME_BYTES`` itself bounds the depth image.
MULTIPART_OVERHEAD = 64 * 1024


class BodyTooLarge(HTTPException):
    """Raised from ``receive`` when a streamed body passes the limit. An HTTPException, so
    FastAPI's body parsing passes it through instead of turning it into a 400."""

    def __init__(self, size: int, max_frame_bytes: int, path: str = "") -> None:
        super().__init__(413, too_large_message(size, max_frame_bytes, path))


def too_large_message(size: int, max_frame_bytes: int, path: str = "") -> str:
    """The 413 detail, the same whether the size was declared or counted. For a frame upload it
    spells out the sum, so the limit it names is not mistaken for a different
    ``VGN_MAX_FRAME_BYTES``; other requests carry no depth image, so theirs does not mention one."""
    limit = max_frame_bytes + MULTIPART_OVERHEAD
    if not path.endswith("/frames"):
        return f"request body of {size}+ bytes exceeds the limit of {limit} bytes"
    return (
        f"request body of {size}+ bytes exceeds the limit of {limit} bytes: "
        f"VGN_MAX_FRAME_BYTES={max_frame_bytes} for the depth image plus {MULTIPART_OVERHEAD} for the "
        "frame's meta and multipart headers"
    )


class BodySizeLimit:
    """ASGI middleware: 413 when ``Content-Length`` exceeds ``max_frame_bytes`` plus
    ``MULTIPART_OVERHEAD``, or when a body without one (chunked) grows past that while it is read.
    The depth image's own limit, ``max_frame_bytes``, is checked where the frame is parsed."""

    def __init__(self, app: ASGIApp, max_frame_bytes: int) -> None:
        self.app = app
        self.max_frame_bytes = max_frame_bytes
        self.max_bytes = max_frame_bytes + MULTIPART_OVERHEAD

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Check the declared length up front, then count the body as the app reads it."""
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        declared = dict(scope["headers"]).get(b"content-length")
        path = scope.get("path", "")
        if declared is not None and declared.isdigit() and int(declared) > self.max_bytes:
            await self._reject(send, int(declared), path)
            return
        received = 0
        response_started = False

        async def counting_receive() -> Message:
            nonlocal received
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > self.max_bytes:
                    raise BodyTooLarge(received, self.max_frame_bytes, path)
            return message

        async def tracking_send(message: Message) -> None:
            nonlocal response_started
            response_started = response_started or message["type"] == "http.response.start"
            await send(message)

        try:
            await self.app(scope, counting_receive, tracking_send)
        except BodyTooLarge:
            if not response_started:
                await self._reject(send, received, path)

    async def _reject(self, send: Send, size: int, path: str) -> None:
        body = json.dumps({"detail": too_large_message(size, self.max_frame_bytes, path)}).encode()
        await send(
            {
                "type": "http.response.start",
                "status": 413,
                "headers": [
                    (b"content-type", b"application/json"),
                    (b"content-length", str(len(body)).encode()),
                ],
            }
        )
        await send({"type": "http.response.body", "body": body})
