"""A TCP relay that delays every chunk by a fixed time each way: link latency where tc netem is missing.

    python tests/delay_relay.py DELAY_MS TARGET_HOST:PORT LISTEN_HOST:PORT [LISTEN_HOST:PORT ...]

Order is kept per direction; a chunk leaves DELAY_MS after it arrived. Runs until killed.
"""

from __future__ import annotations

import asyncio
import contextlib
import sys
import time


async def _pump(reader: asyncio.StreamReader, writer: asyncio.StreamWriter, delay_s: float) -> None:
    queue: asyncio.Queue[tuple[float, bytes]] = asyncio.Queue()

    async def send() -> None:
        while True:
            due, data = await queue.get()
            if not data:
                break
            await asyncio.sleep(max(0.0, due - time.monotonic()))
            writer.write(data)
            await writer.drain()
        writer.close()

    sender = asyncio.create_task(send())
    try:
        while data := await reader.read(65536):
            queue.put_nowait((time.monotonic() + delay_s, data))
    except ConnectionError:
        pass
    queue.put_nowait((0.0, b""))
    with contextlib.suppress(ConnectionError):
        await sender


async def main(delay_s: float, target: tuple[str, int], listens: list[tuple[str, int]]) -> None:
    async def handle(r: asyncio.StreamReader, w: asyncio.StreamWriter) -> None:
        try:
            tr, tw = await asyncio.open_connection(*target)
        except OSError:
            w.close()
            return
        await asyncio.gather(_pump(r, tw, delay_s), _pump(tr, w, delay_s), return_exceptions=True)

    servers = [await asyncio.start_server(handle, host, port) for host, port in listens]
    print("ready", flush=True)
    await asyncio.gather(*(s.serve_forever() for s in servers))


def _addr(text: str) -> tuple[str, int]:
    host, port = text.rsplit(":", 1)
    return host, int(port)


if __name__ == "__main__":
    asyncio.run(main(float(sys.argv[1]) / 1000.0, _addr(sys.argv[2]), [_addr(a) for a in sys.argv[3:]]))
