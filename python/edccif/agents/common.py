"""Names every part of the agents shares: the message kinds, their key expressions and the error type."""

from __future__ import annotations

from .. import _edccif

KINDS = ("measurement", "contribution", "information", "estimate")
"""Message kinds, as in the key expressions and the wire format."""


class AgentError(_edccif.EdccifError):
    """A swarm file or an agent run is invalid (a ``ValueError``)."""


def key(swarm: int, node: int, kind: str) -> str:
    """The key expression of ``kind`` messages of ``node`` in ``swarm``.

    >>> key(1, 3, "contribution")
    'edccif/1/3/contribution'
    """
    return f"edccif/{swarm}/{node}/{kind}"
