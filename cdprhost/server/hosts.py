"""The names the server answers to: the ``Host`` header checked against the listen address.

A web page on another site can make a browser talk to this server by giving its own name the
server's address (DNS rebinding): the browser then sends that site's name as ``Host``. So a
request is answered only when its ``Host`` is a name of this server: the listen address
itself, the loopback names when it listens on loopback, this machine's host names (and
``NAME.local``) when it listens on every address, and the names the user allows
(``--allow-host``). An IP address given as ``Host`` cannot be rebound, and is accepted when
the server listens on every address. The port is not compared (a rebinding page uses the
server's port anyway). Pure functions and one frozen value.
"""

from __future__ import annotations

import ipaddress
import socket
from collections.abc import Iterable
from dataclasses import dataclass

LOOPBACK = frozenset({"localhost", "localhost.localdomain", "ip6-localhost", "127.0.0.1", "::1"})
WILDCARD = frozenset({"", "0.0.0.0", "::"})


def host_name(header: str) -> str:
    """The name in a ``Host`` header: lower case, no port, no brackets, no final dot."""
    text = header.strip().lower()
    if text.startswith("["):
        return text[1:].partition("]")[0]
    if text.count(":") == 1:
        text = text.partition(":")[0]
    return text.rstrip(".")


def _ip(name: str) -> ipaddress.IPv4Address | ipaddress.IPv6Address | None:
    try:
        return ipaddress.ip_address(name)
    except ValueError:
        return None


def machine_names() -> set[str]:
    """This machine's own names (host name, its ``.local`` form, the fully qualified one)."""
    names = set()
    for name in (socket.gethostname(), socket.getfqdn()):
        name = name.lower().rstrip(".")
        if name:
            names |= {name, name.split(".")[0] + ".local"}
    return names


@dataclass(frozen=True)
class HostNames:
    names: frozenset[str]
    any_ip: bool = False  # listening on every address: any IP literal is accepted

    @classmethod
    def for_listen(cls, host: str, allowed: Iterable[str] = ()) -> HostNames:
        """The names a server listening on ``host`` answers to, plus ``allowed``."""
        extra = {host_name(a) for a in allowed if a.strip()}
        listen = host_name(host) if host not in WILDCARD else host
        ip = _ip(listen)
        if listen in WILDCARD:
            return cls(frozenset(LOOPBACK | machine_names() | extra), any_ip=True)
        if listen in LOOPBACK or (ip is not None and ip.is_loopback):
            return cls(frozenset(LOOPBACK | {listen} | extra))
        return cls(frozenset({listen} | extra))

    def allows(self, header: str | None) -> bool:
        """``header``: the request's ``Host`` (None: none sent, an HTTP/1.0 client)."""
        if header is None:
            return True
        name = host_name(header)
        if name in self.names:
            return True
        ip = _ip(name)
        return ip is not None and (self.any_ip or (ip.is_loopback and "127.0.0.1" in self.names))
