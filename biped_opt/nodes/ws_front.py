"""The Foxglove bridge's front door: the WebSocket subprotocols it accepts (ROS.md Sec. 7).

The ``foxglove-sdk`` server accepts a WebSocket connection only when the client offers the
subprotocol ``foxglove.sdk.v1`` (as the Foxglove app and the ROS ``foxglove_bridge`` 3.x do);
anything else gets HTTP 400 with the body "Missing expected sec-websocket-protocol header",
which names neither the protocol nor the way out. Clients written against the older
``@foxglove/ws-protocol`` (``foxglove.websocket.v1``: the ROS ``foxglove_bridge`` before 3.0, its
client libraries and tools built on them) speak the same messages: the SDK's protocol is that
protocol under a new name, and for a server that advertises no capability (this bridge) the
messages it sends -- ``serverInfo``, ``status``, ``advertise``, ``unadvertise``, ``removeStatus``
and binary message data -- are the ones ws-protocol defines (the project's tests drive the bridge
with ws-protocol's own client library).

:class:`SubprotocolFront` listens on the bridge's address and, for each connection, reads the
HTTP upgrade request (at most :data:`HEAD_MAX` bytes within :data:`HANDSHAKE_S` seconds), then:

- ``foxglove.sdk.v1`` offered: passes the connection through to the SDK's server unchanged;
- ``foxglove.websocket.v1`` offered (and not the former): passes it through with the request
  asking for ``foxglove.sdk.v1`` and the server's answer naming ``foxglove.websocket.v1``, the
  one the client offered (a WebSocket client drops a connection whose answer names another);
- otherwise answers ``400 Bad Request`` itself, the body naming the subprotocols accepted and
  what the client offered.

After the handshake it copies bytes both ways and nothing else; a client that stops reading
stops the copy towards it, so the SDK's per-client queue (and its bound) still applies. At most
:data:`MAX_CONNECTIONS` connections at a time; one more is closed at once.
"""

from __future__ import annotations

import socket
import threading
from collections.abc import Iterable

__all__ = ["SubprotocolFront", "SUBPROTOCOL", "LEGACY_SUBPROTOCOL", "HEAD_MAX", "HANDSHAKE_S",
           "MAX_CONNECTIONS", "offered_subprotocols"]

#: the SDK's subprotocol, and the older name of the same protocol also accepted
SUBPROTOCOL = "foxglove.sdk.v1"
LEGACY_SUBPROTOCOL = "foxglove.websocket.v1"
#: the largest HTTP request or response head read [bytes], and the time a client has to send it
HEAD_MAX = 16 << 10
HANDSHAKE_S = 10.0
#: connections served at a time
MAX_CONNECTIONS = 64
_CHUNK = 64 << 10


def offered_subprotocols(head: bytes) -> list[str]:
    """The subprotocols a WebSocket upgrade request offers (every ``Sec-WebSocket-Protocol``
    header, comma-separated values), in order."""
    out: list[str] = []
    for line in head.split(b"\r\n")[1:]:
        name, sep, value = line.partition(b":")
        if sep and name.strip().lower() == b"sec-websocket-protocol":
            out += [v.strip() for v in value.decode("latin-1").split(",") if v.strip()]
    return out


def _replace_protocol(head: bytes, value: str) -> bytes:
    """``head`` with its ``Sec-WebSocket-Protocol`` header(s) replaced by one naming
    ``value``."""
    lines = head.split(b"\r\n")
    kept = [lines[0]] + [ln for ln in lines[1:] if ln.partition(b":")[0].strip().lower()
                         != b"sec-websocket-protocol"]
    # (the head ends with an empty line, and so with two empty items after the split)
    while kept and kept[-1] == b"":
        kept.pop()
    kept.append(b"Sec-WebSocket-Protocol: " + value.encode())
    return b"\r\n".join(kept) + b"\r\n\r\n"


def _read_head(sock: socket.socket) -> tuple[bytes, bytes] | None:
    """(the HTTP head up to its blank line, the bytes read after it), or None when the peer
    closes, sends more than :data:`HEAD_MAX` bytes without ending it, or times out."""
    data = b""
    while b"\r\n\r\n" not in data:
        if len(data) > HEAD_MAX:
            return None
        try:
            chunk = sock.recv(4096)
        except OSError:
            return None
        if not chunk:
            return None
        data += chunk
    end = data.index(b"\r\n\r\n") + 4
    if end > HEAD_MAX:
        return None
    return data[:end], data[end:]


def refusal(offered: Iterable[str]) -> bytes:
    """The HTTP 400 answer to a client that offers neither subprotocol."""
    names = ", ".join(offered) or "none"
    body = (f"This is a Foxglove WebSocket server (biped_opt foxglove_bridge). Connect with the "
            f"WebSocket subprotocol {SUBPROTOCOL} (the Foxglove app, foxglove-sdk clients, "
            f"foxglove_bridge 3.x) or {LEGACY_SUBPROTOCOL} (@foxglove/ws-protocol clients); "
            f"this request offered: {names}.\n").encode()
    return (b"HTTP/1.1 400 Bad Request\r\nContent-Type: text/plain; charset=utf-8\r\n"
            b"Content-Length: " + str(len(body)).encode() + b"\r\nConnection: close\r\n\r\n"
            + body)


class SubprotocolFront:
    """Listens on ``(host, port)`` (port 0: any free one, see :attr:`port`) in front of the
    WebSocket server at ``127.0.0.1:backend_port`` (see the module docstring)."""

    def __init__(self, host: str, port: int, backend_port: int) -> None:
        self.backend = ("127.0.0.1", int(backend_port))
        self._listener = socket.create_server((host, port), reuse_port=False)
        self._listener.settimeout(0.2)
        self.port: int = self._listener.getsockname()[1]
        self._lock = threading.Lock()
        self._open: set[socket.socket] = set()
        self._stopping = threading.Event()
        self._thread = threading.Thread(target=self._accept, name="ws-front", daemon=True)
        self._thread.start()

    @property
    def connections(self) -> int:
        """Sockets open now (clients and their passages to the server)."""
        with self._lock:
            return len(self._open)

    def _track(self, sock: socket.socket) -> bool:
        with self._lock:
            if self._stopping.is_set():
                return False
            self._open.add(sock)
            return True

    def _close(self, *socks: socket.socket) -> None:
        for sock in socks:
            with self._lock:
                self._open.discard(sock)
            try:  # (shutdown wakes the other direction's thread blocked in recv)
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            sock.close()

    def _accept(self) -> None:
        while not self._stopping.is_set():
            try:
                client, _address = self._listener.accept()
            except TimeoutError:
                continue
            except OSError:
                return  # (closed by stop)
            with self._lock:
                full = len(self._open) >= 2 * MAX_CONNECTIONS
            if full or not self._track(client):
                client.close()
                continue
            threading.Thread(target=self._serve, args=(client,), name="ws-front-conn",
                             daemon=True).start()

    def _serve(self, client: socket.socket) -> None:
        client.settimeout(HANDSHAKE_S)
        read = _read_head(client)
        if read is None:
            self._close(client)
            return
        head, rest = read
        offered = offered_subprotocols(head)
        if SUBPROTOCOL in offered:
            answer_as = None
        elif LEGACY_SUBPROTOCOL in offered:
            answer_as = LEGACY_SUBPROTOCOL
            head = _replace_protocol(head, SUBPROTOCOL)
        else:
            try:
                client.sendall(refusal(offered))
            except OSError:
                pass
            self._close(client)
            return
        try:
            server = socket.create_connection(self.backend, timeout=HANDSHAKE_S)
        except OSError:
            self._close(client)
            return
        if not self._track(server):
            self._close(client, server)
            return
        try:
            server.sendall(head + rest)
            reply = _read_head(server)
            if reply is None:
                raise OSError("no answer")
            answer, after = reply
            if answer_as is not None and offered_subprotocols(answer) == [SUBPROTOCOL]:
                answer = _replace_protocol(answer, answer_as)
            client.sendall(answer + after)
        except OSError:
            self._close(client, server)
            return
        client.settimeout(None)
        server.settimeout(None)
        threading.Thread(target=self._copy, args=(server, client), name="ws-front-down",
                         daemon=True).start()
        self._copy(client, server)

    def _copy(self, source: socket.socket, sink: socket.socket) -> None:
        """Bytes from ``source`` to ``sink`` until either ends; then both are closed."""
        try:
            while True:
                data = source.recv(_CHUNK)
                if not data:
                    break
                sink.sendall(data)
        except OSError:
            pass
        self._close(source, sink)

    def stop(self) -> None:
        """Stop listening and close every connection."""
        self._stopping.set()
        try:
            self._listener.close()
        except OSError:
            pass
        with self._lock:
            socks, self._open = list(self._open), set()
        for sock in socks:
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            try:
                sock.close()
            except OSError:
                pass
        self._thread.join(timeout=2.0)
