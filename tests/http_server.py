"""An app served for real: uvicorn on a free loopback port in a thread, and an HTTP client to it.

The API's tests talk HTTP over TCP as a browser or curl does (not an in-process transport), so what they check
includes uvicorn's request parsing, the app's lifespan and what goes over the socket.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

import httpx
import uvicorn


@contextmanager
def served(app, timeout_s: float = 30.0) -> Iterator[httpx.Client]:
    """Serve `app` on 127.0.0.1 (a port the OS picks) while the block runs; yields a client whose base URL
    is the server. The server's lifespan runs at start and at exit, as under `spinefarm api`."""
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=0, log_level="warning", lifespan="on"))
    thread = threading.Thread(target=server.run, name="served-app", daemon=True)
    thread.start()
    deadline = time.monotonic() + timeout_s
    while not server.started:
        if not thread.is_alive() or time.monotonic() > deadline:
            server.should_exit = True
            raise RuntimeError(f"the app did not start serving within {timeout_s} s")
        time.sleep(0.01)
    port = server.servers[0].sockets[0].getsockname()[1]
    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=timeout_s) as client:
            yield client
    finally:
        server.should_exit = True
        thread.join(timeout_s)
