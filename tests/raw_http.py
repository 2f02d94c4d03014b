"""Raw-socket HTTP for the servers' hostile-load tests: which status each of many simultaneous
connections gets, or why it got none."""

from __future__ import annotations

import asyncio
import socket
from pathlib import Path


async def status_of(host: str, port: int, request: bytes) -> str:
    """The status code of the answer to `request` on a new connection; "reset", the name of another
    OSError, or "no answer" when the server closed without one."""
    try:
        reader, writer = await asyncio.open_connection(host, port)
        writer.write(request)
        await writer.drain()
        data = await reader.read()
        writer.close()
    except ConnectionResetError:
        return "reset"
    except OSError as exc:
        return type(exc).__name__
    return data.split(b" ", 2)[1].decode() if data else "no answer"


def burst_statuses(host: str, port: int, request: bytes, count: int, timeout_s: float) -> list[str]:
    """`count` connections at once, each sending `request`: `status_of` each, or "no answer in N s"."""

    async def within() -> str:
        try:
            return await asyncio.wait_for(status_of(host, port, request), timeout=timeout_s)
        except TimeoutError:
            return f"no answer in {timeout_s:g} s"

    async def burst() -> list[str]:
        return await asyncio.gather(*(within() for _ in range(count)))

    return asyncio.run(burst())


def send_raw(address: tuple[str, int], request: bytes, timeout: float = 30.0) -> bytes:
    """`request` as bytes on a new socket (HTTP client libraries refuse what a hostile client sends) and
    everything the server sent back; a connection closed without an answer fails the test."""
    with socket.create_connection(address, timeout=timeout) as sock:
        sock.sendall(request)
        data = b""
        try:
            while chunk := sock.recv(65536):
                data += chunk
        except ConnectionResetError:
            if not data:  # a reset after a whole answer is the kernel refusing the unread rest of a request
                raise
    assert data, f"{request[:80]!r}: the connection closed without an answer"
    return data


def memory_kb(pid: int) -> dict[str, int]:
    """VmRSS, VmHWM (kB) and Threads of a process, from /proc."""
    fields = {}
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(("VmRSS:", "VmHWM:", "Threads:")):
            name, value = line.split(":")
            fields[name] = int(value.split()[0])
    return fields
