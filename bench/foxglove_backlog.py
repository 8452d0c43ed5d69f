"""What Foxglove clients that never read cost the live bridge (``biped-opt node foxglove``).

Starts the bridge in a process of its own, connects ``--clients`` WebSocket clients that
subscribe to one topic and then never read (a raw client: the handshake, one subscribe, a
small receive buffer), and has a DDS peer publish ``--messages`` messages of ``--size`` bytes
on that topic (``std_msgs/msg/String``). Prints the bridge's resident memory before and after,
and whether the clients are still connected.

    python bench/foxglove_backlog.py [--clients 2] [--messages 1024] [--size 262144]
                                     [--param client_queue_bytes:=N ...]

Each client's queue is bounded by the parameter ``client_queue_bytes`` (ROS.md "Live view in
Foxglove"); before that bound, 2 such clients and 1024 messages of 256 KB took the bridge from
63 MB to 580 MB.
"""

from __future__ import annotations

import argparse
import base64
import json
import os
import socket
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("ROS_LOCALHOST_ONLY", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _frame(payload: bytes, opcode: int = 1) -> bytes:
    """A client's WebSocket frame (FIN, masked with a zero key: clients must mask)."""
    head = bytes([0x80 | opcode])
    if len(payload) < 126:
        head += bytes([0x80 | len(payload)])
    elif len(payload) < 1 << 16:
        head += bytes([0x80 | 126]) + struct.pack(">H", len(payload))
    else:
        head += bytes([0x80 | 127]) + struct.pack(">Q", len(payload))
    return head + bytes(4) + payload


def _read_frame(sock: socket.socket) -> tuple[int, bytes]:
    def exactly(n: int) -> bytes:
        data = b""
        while len(data) < n:
            piece = sock.recv(n - len(data))
            if not piece:
                raise ConnectionError("closed")
            data += piece
        return data

    first, second = exactly(2)
    size = second & 0x7F
    if size == 126:
        size = struct.unpack(">H", exactly(2))[0]
    elif size == 127:
        size = struct.unpack(">Q", exactly(8))[0]
    return first & 0x0F, exactly(size)


class DeafClient:
    """A Foxglove WebSocket client that subscribes to ``topic`` and then reads nothing."""

    def __init__(self, port: int, topic: str, timeout: float = 30.0) -> None:
        sock = socket.socket()
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        sock.connect(("127.0.0.1", port))
        key = base64.b64encode(os.urandom(16)).decode()
        sock.sendall((f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
                      f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                      "Sec-WebSocket-Version: 13\r\n"
                      "Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n").encode())
        head = b""
        while b"\r\n\r\n" not in head:
            head += sock.recv(1)
        if b" 101 " not in head.split(b"\r\n")[0]:
            raise ConnectionError(f"no WebSocket upgrade: {head[:80]!r}")
        deadline = time.monotonic() + timeout
        channel = None
        sock.settimeout(timeout)
        while channel is None and time.monotonic() < deadline:
            opcode, payload = _read_frame(sock)
            if opcode != 1:
                continue
            message = json.loads(payload)
            if message.get("op") == "advertise":
                channel = next((c["id"] for c in message["channels"] if c["topic"] == topic),
                               None)
        if channel is None:
            raise TimeoutError(f"{topic} was not advertised")
        sock.sendall(_frame(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": 1, "channelId": channel}]}).encode()))
        self.sock = sock

    def connected(self) -> bool:
        """Whether the server still keeps the connection (it closes a client it gives up)."""
        try:
            self.sock.setblocking(False)
            return self.sock.recv(1, socket.MSG_PEEK) != b""
        except BlockingIOError:
            return True
        except OSError:
            return False
        finally:
            self.sock.setblocking(True)

    def close(self) -> None:
        self.sock.close()


def rss_kib(pid: int) -> int:
    with open(f"/proc/{pid}/status", encoding="ascii") as fh:
        return next(int(line.split()[1]) for line in fh if line.startswith("VmRSS:"))


def start_bridge(domain_id: int, parameters: list[str]) -> tuple[subprocess.Popen, int]:
    """``biped-opt node foxglove`` on a free port; (process, port) once it is ready."""
    args = [sys.executable, "-m", "biped_opt.cli.main", "node", "foxglove", "--ros-args",
            "-p", "port:=0", "-p", "discovery_period:=0.2"]
    for parameter in parameters:
        args += ["-p", parameter]
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id), "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(args, env=env, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL,
                            text=True)
    assert proc.stderr is not None
    for line in proc.stderr:
        if "ready: serving ws://" in line:
            port = int(line.rsplit(":", 1)[1].split()[0])
            threading.Thread(target=lambda: [None for _ in proc.stderr],  # type: ignore
                             daemon=True).start()
            return proc, port
    raise RuntimeError(f"the bridge exited with status {proc.wait()}")


def measure(domain_id: int, clients: int, messages: int, size: int,
            parameters: list[str]) -> dict[str, Any]:
    from biped_opt import ros

    topic = "/bench/big"
    proc, port = start_bridge(domain_id, parameters)
    context = ros.Context()
    ros.init(args=[], context=context, domain_id=domain_id)
    node = ros.Node("big_publisher", context=context)
    string = ros.message_type("std_msgs/msg/String")
    publisher = node.create_publisher(string, topic, ros.QoSProfile(depth=10))
    deaf: list[DeafClient] = []
    try:
        deadline = time.monotonic() + 30
        while not deaf and time.monotonic() < deadline:
            publisher.publish(string(data="x"))  # (the bridge serves a topic with a publisher)
            try:
                deaf = [DeafClient(port, topic, timeout=2.0) for _ in range(clients)]
            except (TimeoutError, ConnectionError):
                deaf = []
        before = rss_kib(proc.pid)
        text = "y" * size
        for _ in range(messages):
            publisher.publish(string(data=text))
            time.sleep(0.002)
        time.sleep(2.0)
        after = rss_kib(proc.pid)
        return {"clients": clients, "messages": messages, "size": size,
                "rss_before_mib": before / 1024, "rss_after_mib": after / 1024,
                "still_connected": sum(c.connected() for c in deaf),
                "parameters": parameters}
    finally:
        for client in deaf:
            client.close()
        node.destroy_node()
        ros.try_shutdown(context=context)
        proc.terminate()
        proc.wait(30)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clients", type=int, default=2)
    parser.add_argument("--messages", type=int, default=1024)
    parser.add_argument("--size", type=int, default=256 * 1024)
    parser.add_argument("--domain-id", type=int, default=1 + os.getpid() % 200)
    parser.add_argument("--param", action="append", default=[], metavar="NAME:=VALUE",
                        help="a parameter of the bridge (repeat for more)")
    args = parser.parse_args()
    parameters = args.param
    result = measure(args.domain_id, args.clients, args.messages, args.size, parameters)
    print(f"{result['clients']} clients that never read, {result['messages']} messages of "
          f"{result['size']} bytes: bridge RSS {result['rss_before_mib']:.0f} -> "
          f"{result['rss_after_mib']:.0f} MiB; {result['still_connected']} of "
          f"{result['clients']} clients still connected"
          + (f" ({', '.join(parameters)})" if parameters else ""))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
