"""Hostile recordings through the commands that read them: ``info``, ``report``, ``replay``.

A tester hands the CLI files that are not what they claim, and a writer can put anything in a
file with valid CRCs. Three kinds, each made here (:func:`cases`):

- *bombs*: a 49 KB file of one zstd chunk that inflates to 1.5 GB of zeros (no footer), the
  same declaring a small size, the same with lz4, many chunks each within the budget;
- *special files*: ``/dev/zero``, a FIFO nobody writes, a directory, an empty file, a symlink
  to ``/dev/zero``;
- *CRC-valid hostile records*, rewritten from a real sweep recording by the ``mcap`` writer
  (every CRC right): a ``/biped/sweep`` message cut to 7 bytes, messages of random bytes, log
  times near 2^64, sweep points with a NaN angle or a contact mode of 200, a system_info that
  does not decode.

Each file goes through each command in a process of its own (address space capped at
``--memory-cap``, ``--timeout`` to finish), and the run reports, per case and command, the exit
status, the time, the peak resident memory and the first line on stderr. A command passes when
it exits 0 or 2 within the timeout, prints no traceback and says at most three lines on stderr;
the exit status is 1 when any does not.

    python bench/recording_fuzz.py [--sample N] [--seed S] [--timeout 60] [--json]

``tests/record/test_hostile_recordings.py`` runs a sample of the same cases in every test run.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import struct
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path

os.environ.setdefault("ROS_LOCALHOST_ONLY", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

MAGIC = b"\x89MCAP0\r\n"
#: opcodes of the records a bomb is made of (MCAP specification)
HEADER, CHUNK, DATA_END, FOOTER = 0x01, 0x06, 0x0F, 0x02


def _record(opcode: int, body: bytes) -> bytes:
    return struct.pack("<BQ", opcode, len(body)) + body


def _text(value: bytes) -> bytes:
    return struct.pack("<I", len(value)) + value


def _zeros(total: int, compression: str) -> bytes:
    """``total`` zero bytes compressed as one frame, made block by block."""
    block = bytes(1 << 20)
    if compression == "zstd":
        import zstandard

        out = zstandard.ZstdCompressor(level=3, write_content_size=False).compressobj()
        parts = [out.compress(block) for _ in range(total // len(block))]
        return b"".join(parts) + out.compress(bytes(total % len(block))) + out.flush()
    import lz4.frame

    compressor = lz4.frame.LZ4FrameCompressor()
    parts = [compressor.begin()]
    parts += [compressor.compress(block) for _ in range(total // len(block))]
    return b"".join(parts) + compressor.compress(bytes(total % len(block))) + compressor.flush()


def bomb(path: Path, *, inflated: int = 1_500_000_000, declared: int | None = None,
         compression: str = "zstd", chunks: int = 1, footer: bool = False) -> Path:
    """A file of ``chunks`` chunks, each ``inflated`` zero bytes compressed, declaring
    ``declared`` (default: the truth) uncompressed bytes and no CRC."""
    data = _zeros(inflated, compression)
    head = struct.pack("<QQQI", 0, 0, inflated if declared is None else declared, 0)
    chunk = _record(CHUNK, head + _text(compression.encode()) + struct.pack("<Q", len(data))
                    + data)
    out = MAGIC + _record(HEADER, _text(b"ros2") + _text(b"bomb")) + chunk * chunks
    if footer:
        out += _record(DATA_END, struct.pack("<I", 0)) + _record(FOOTER, bytes(20)) + MAGIC
    path.write_bytes(out)
    return path


def rewrite(source: Path, path: Path, mutate: Callable[[list[list]], None]) -> Path:
    """``source`` written again by the ``mcap`` writer (so every CRC is right) after
    ``mutate`` changed its messages, a list of [topic, log_time, publish_time, data]."""
    from mcap.writer import CompressionType, Writer

    from biped_opt.record.reader import read_raw
    from biped_opt.record.writer import sealed

    raw = read_raw(source)
    messages = [[m.topic, m.log_time_ns, m.publish_time_ns, m.data] for m in raw.messages]
    mutate(messages)
    with open(path, "wb") as stream:
        writer = Writer(stream, compression=CompressionType.ZSTD, enable_data_crcs=True)
        writer.start(profile="ros2", library="recording_fuzz")
        schemas: dict[str, int] = {}
        ids: dict[str, int] = {}
        for topic, ch in raw.channels.items():
            if ch.type not in schemas:
                schemas[ch.type] = writer.register_schema(
                    name=ch.type, encoding=ch.schema_encoding, data=ch.schema_data)
            ids[topic] = writer.register_channel(topic=topic, message_encoding=ch.message_encoding,
                                                 schema_id=schemas[ch.type], metadata=ch.metadata)
        for seq, (topic, log_time, publish_time, data) in enumerate(messages):
            writer.add_message(ids[topic], log_time=log_time, data=data,
                               publish_time=publish_time, sequence=seq)
        for name, values in raw.metadata.items():
            writer.add_metadata(name, sealed(name, values))
        writer.finish()
    return path


def _sweep_point(data: bytes, **changes: object) -> bytes:
    """A SweepPoint's CDR with fields changed (serialized again: a well-formed message)."""
    import dataclasses

    from biped_opt.ros.interfaces import load_interfaces

    store = load_interfaces().typestore
    kind = "biped_opt_interfaces/msg/SweepPoint"
    return bytes(store.serialize_cdr(dataclasses.replace(store.deserialize_cdr(data, kind),
                                                         **changes), kind))


def _first(messages: list[list], topic: str) -> list:
    return next(m for m in messages if m[0] == topic)


def hostile_rewrites(rng: random.Random) -> dict[str, Callable[[list[list]], None]]:
    """The CRC-valid mutations of a sweep recording, by name."""
    import numpy as np

    def cut(messages: list[list]) -> None:
        _first(messages, "/biped/sweep")[3] = _first(messages, "/biped/sweep")[3][:7]

    def garble(messages: list[list]) -> None:
        for m in rng.sample(messages, k=min(20, len(messages))):
            m[3] = rng.randbytes(rng.randrange(0, 64))
        for m in [m for m in messages if m[0] == "/biped/sweep"][:3]:
            m[3] = m[3][:4] + rng.randbytes(len(m[3]) - 4)

    def late(messages: list[list]) -> None:
        for k, m in enumerate(messages[-3:]):
            m[1] = m[2] = (1 << 64) - 1 - k
        messages[0][1] = (1 << 63) - 5  # (the last representable nanoseconds, kept)

    def absurd(messages: list[list]) -> None:
        points = [m for m in messages if m[0] == "/biped/sweep"]
        points[0][3] = _sweep_point(points[0][3], theta0=float("nan"))
        points[1][3] = _sweep_point(points[1][3], mode_sequence=np.array([0, 200], np.uint8))
        points[2][3] = _sweep_point(points[2][3], policy=np.zeros(7))

    def every_sweep_point_cut(messages: list[list]) -> None:
        for m in messages:
            if m[0] == "/biped/sweep":
                m[3] = m[3][:7]

    return {"sweep point cut to 7 bytes": cut, "random bytes in messages": garble,
            "log times near 2^64": late, "absurd sweep points": absurd,
            "every sweep point cut": every_sweep_point_cut}


def cases(folder: Path, source: Path | None, seed: int = 1) -> Iterator[tuple[str, Path]]:
    """(name, path) of every hostile file, made in ``folder`` (``source``: a real sweep
    recording to rewrite; None leaves those out)."""
    yield "zstd bomb: 49 KB to 1.5 GB, no footer", bomb(folder / "bomb.mcap")
    yield "zstd bomb declaring 1 MB", bomb(folder / "bomb_small.mcap", declared=1 << 20)
    yield "lz4 bomb: 256 MB, with footer", bomb(folder / "bomb.lz4.mcap", inflated=256 << 20,
                                               compression="lz4", footer=True)
    yield "200 chunks of 4 MB zeros", bomb(folder / "many.mcap", inflated=4 << 20, chunks=200)
    yield "/dev/zero", Path("/dev/zero")
    fifo = folder / "fifo.mcap"
    if not fifo.exists():
        os.mkfifo(fifo)
    yield "a FIFO nobody writes", fifo
    yield "a directory", folder
    (folder / "empty.mcap").write_bytes(b"")
    yield "an empty file", folder / "empty.mcap"
    link = folder / "zero_link.mcap"
    if not link.is_symlink():
        link.symlink_to("/dev/zero")
    yield "a symlink to /dev/zero", link
    if source is not None:
        rng = random.Random(seed)
        for name, mutate in hostile_rewrites(rng).items():
            slug = "".join(c if c.isalnum() else "_" for c in name)[:40]
            yield f"CRC-valid: {name}", rewrite(source, folder / f"{slug}.mcap", mutate)


def sweep_recording(folder: Path) -> Path:
    """A small fixed-input touchdown sweep recorded through the nodes (the file the CRC-valid
    cases rewrite)."""
    out = folder / "sweep.mcap"
    if not out.exists():
        subprocess.run([sys.executable, "-m", "biped_opt.cli.main", "record", "--maneuver",
                        "touchdown", "--theta0-min", "-0.1", "--theta0-max", "0.1", "--num", "9",
                        "--out", str(out)], check=True, capture_output=True,
                       env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=600)
    return out


#: runs a command as its child and reports its exit status and peak memory: a process forked
#: from a large one (a test run) starts with that one's resident pages counted in its peak, so
#: the command is forked from this small interpreter instead
_MEASURE = """
import json, os, resource, sys
cap, argv = int(sys.argv[1]), sys.argv[2:]
pid = os.fork()
if pid == 0:
    resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, 1)
    os.execv(argv[0], argv)
_, code, usage = os.wait4(pid, 0)
print(json.dumps({"status": os.waitstatus_to_exitcode(code), "maxrss": usage.ru_maxrss}))
"""


def run_command(args: list[str], *, timeout: float, memory_cap: int) -> dict:
    """``biped-opt args...`` in a process of its own: status (None: killed at ``timeout``),
    seconds, peak resident memory [MiB], stderr's line count and first line."""
    start = time.monotonic()
    proc = subprocess.Popen(
        [sys.executable, "-S", "-c", _MEASURE, str(memory_cap), sys.executable, "-m",
         "biped_opt.cli.main", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True, env={**os.environ, "PYTHONPATH": str(ROOT)}, start_new_session=True)
    try:
        out, err = proc.communicate(timeout=timeout)
        measured = json.loads(out.strip().splitlines()[-1])
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, 9)
        out, err = proc.communicate()
        measured = {"status": None, "maxrss": 0}
    lines = [line for line in err.splitlines() if line.strip()]
    return {"status": measured["status"], "seconds": time.monotonic() - start,
            "peak_mib": measured["maxrss"] / 1024, "lines": len(lines),
            "first": lines[0] if lines else "", "traceback": "Traceback" in err}


def commands(path: Path, out: Path, domain_id: int) -> dict[str, list[str]]:
    return {"info": ["info", str(path)],
            "report": ["report", str(path), "--out", str(out)],
            "replay": ["replay", str(path), "--rate", "1000", "--delay", "0",
                       "--domain-id", str(domain_id)]}


def passed(result: dict) -> bool:
    return result["status"] in (0, 2) and not result["traceback"] and result["lines"] <= 3


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sample", type=int, default=0,
                        help="run this many cases, chosen with --seed (default: all)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--timeout", type=float, default=60.0, help="per command [s]")
    parser.add_argument("--memory-cap", type=int, default=2 << 30, help="address space [bytes]")
    parser.add_argument("--domain-id", type=int, default=1 + os.getpid() % 200)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    failures = 0
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        found = list(cases(folder, sweep_recording(folder), args.seed))
        if args.sample:
            found = random.Random(args.seed).sample(found, min(args.sample, len(found)))
        for name, path in found:
            for command, argv in commands(path, folder / "report", args.domain_id).items():
                result = run_command(argv, timeout=args.timeout, memory_cap=args.memory_cap)
                failures += not passed(result)
                if args.json:
                    print(json.dumps({"case": name, "command": command, **result}), flush=True)
                else:
                    print(f"{'ok  ' if passed(result) else 'FAIL'} {name:<42} {command:<6} "
                          f"status {result['status']}, {result['seconds']:6.2f} s, "
                          f"{result['peak_mib']:6.1f} MiB: {result['first'][:90]}", flush=True)
    return 1 if failures else 0


if __name__ == "__main__":
    raise SystemExit(main())
