"""The header-deadline protocol over uvicorn's httptools implementation (needs ``httptools``)."""

from __future__ import annotations

from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol

from api.protocol import HeaderDeadline


class HeaderDeadlineHttpToolsProtocol(HeaderDeadline, HttpToolsProtocol):
    """:class:`HttpToolsProtocol` that closes connections too slow to send headers."""
