"""Errors of the dend client: the API's own `{code, message}` errors and
undecodable WebSocket frames."""

from __future__ import annotations


class DendError(Exception):
    """An error answered by the server: HTTP status (0 for a WebSocket
    `error` event), the API's stable error `code` (`pose_not_found`,
    `not_ready`, ... as listed in api/openapi.yaml) and its message."""

    def __init__(self, status: int, code: str, message: str) -> None:
        super().__init__(f"{status}: {code}: {message}" if status else f"{code}: {message}")
        self.status = status
        self.code = code
        self.message = message


class FrameError(ValueError):
    """A binary message that is not a pose frame this client can decode
    (wrong magic, an unknown format version, a wrong length)."""
