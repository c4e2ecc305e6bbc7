"""Zenoh: the peer configuration, free loopback ports and the bytes a process sent on its TCP links."""

from __future__ import annotations

import json
import os
import socket
import struct
from typing import Any, Dict, List, Optional, Sequence

from .common import AgentError


def free_ports(n: int) -> List[int]:
    """``n`` distinct TCP ports free on 127.0.0.1 now (the OS picks them)."""
    socks, ports = [], []
    try:
        for _ in range(n):
            s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            s.bind(("127.0.0.1", 0))
            socks.append(s)
            ports.append(s.getsockname()[1])
    finally:
        for s in socks:
            s.close()
    return ports


def _zenoh() -> Any:
    try:
        import zenoh
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise AgentError(
            "the agents need the eclipse-zenoh package: pip install 'edccif[agents]'"
        ) from e
    return zenoh


def zenoh_config(listen: Sequence[str], connect: Sequence[str], base: Optional[str] = None) -> Any:
    """A peer configuration on explicit endpoints with every kind of scouting off, so
    that a process talks exactly to the endpoints it is given. ``base``: a Zenoh
    JSON5 configuration file to start from (TLS, access control; docs/agents.md)."""
    zenoh = _zenoh()
    c = zenoh.Config.from_file(base) if base else zenoh.Config()
    c.insert_json5("mode", '"peer"')
    c.insert_json5("listen/endpoints", json.dumps(list(listen)))
    c.insert_json5("connect/endpoints", json.dumps(list(connect)))
    c.insert_json5("scouting/multicast/enabled", "false")
    c.insert_json5("scouting/gossip/enabled", "false")
    return c


def _port(endpoint: str) -> int:
    return int(endpoint.rsplit(":", 1)[1])


def tcp_bytes(sensor_ports: Sequence[int], agent_ports: Sequence[int]) -> Dict[str, Dict[str, int]]:
    """Bytes this process sent and received on its TCP connections, from the
    kernel (``TCP_INFO``: ``tcpi_bytes_acked``, ``tcpi_bytes_received``), by link
    type: a connection to or from a sensor port is a sensor link, to or from an
    agent port an estimator link. Zenoh's own framing, keep-alives and
    declarations are included; TCP/IP headers are not."""
    out = {"sensor_link": {"sent": 0, "received": 0}, "estimator_link": {"sent": 0, "received": 0}}
    sp, ap = set(sensor_ports), set(agent_ports)
    for fd in os.listdir("/proc/self/fd"):
        try:
            if not os.readlink(f"/proc/self/fd/{fd}").startswith("socket:"):
                continue
            s = socket.socket(fileno=os.dup(int(fd)))
        except (OSError, ValueError):
            continue
        try:
            if s.type != socket.SOCK_STREAM or s.family != socket.AF_INET:
                continue
            try:
                local, peer = s.getsockname()[1], s.getpeername()[1]
            except OSError:
                continue
            info = s.getsockopt(socket.IPPROTO_TCP, socket.TCP_INFO, 256)
            if len(info) < 136:
                continue
            acked, received = struct.unpack_from("QQ", info, 120)
            kind = "sensor_link" if (local in sp or peer in sp) else "estimator_link" if (
                local in ap or peer in ap) else None
            if kind:
                out[kind]["sent"] += acked
                out[kind]["received"] += received
        finally:
            s.close()
    return out
