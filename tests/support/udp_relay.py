"""A UDP relay on 127.0.0.1 between one client and a server: forwards both ways, may drop (seeded), may overhear."""

from __future__ import annotations

import random
import select
import socket
import threading
from collections.abc import Callable


class LossyRelay:
    """Forwards datagrams client <-> server, dropping a seeded share; ``heard`` sees each one from the client."""

    def __init__(self, server_port: int, *, drop: float = 0.0, seed: int = 0,
                 heard: Callable[[bytes], None] = lambda data: None,
                 droppable: Callable[[bytes], bool] = lambda data: True) -> None:
        self.front = bound_socket()  # the client's side
        self.back = bound_socket()  # the server's side
        self.port = self.front.getsockname()[1]
        self.server = ("127.0.0.1", server_port)
        self.drop = drop
        self.rng = random.Random(seed)
        self.forwarded = self.dropped = 0
        self._heard = heard
        self._droppable = droppable  # which datagrams the seeded share is drawn from
        self._client: tuple[str, int] | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            ready, _, _ = select.select([self.front, self.back], [], [], 0.05)
            for sock in ready:
                try:
                    data, addr = sock.recvfrom(65536)
                except OSError:  # ICMP port unreachable from a peer that went away
                    continue
                if sock is self.front:
                    self._client = addr
                    self._heard(data)
                    self._pass(data, self.back, self.server)
                elif self._client is not None:
                    self._pass(data, self.front, self._client)

    def _pass(self, data: bytes, sock: socket.socket, to: tuple[str, int]) -> None:
        if self.drop and self._droppable(data) and self.rng.random() < self.drop:
            self.dropped += 1
        else:
            self.forwarded += 1
            sock.sendto(data, to)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        assert not self._thread.is_alive()
        self.front.close()
        self.back.close()


def bound_socket() -> socket.socket:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    return sock
