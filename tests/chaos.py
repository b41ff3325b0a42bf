"""A UDP proxy on loopback that damages the link between the bridge and the rig.

Every datagram, in either direction, may be dropped, duplicated, corrupted (one byte
flipped) or held back and sent after the next one (reordering), each with its own
probability, from a seeded generator; ``stall(seconds)`` drops everything for a while.
"""
from __future__ import annotations

import random
import select
import socket
import threading
import time


class ChaosProxy:
    def __init__(self, rig_port: int, drop=0.0, duplicate=0.0, corrupt=0.0, reorder=0.0, seed=1):
        self.rig = ("127.0.0.1", rig_port)
        self.p = dict(drop=drop, duplicate=duplicate, corrupt=corrupt, reorder=reorder)
        self.rng = random.Random(seed)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)        # faces the bridge
        self.sock.bind(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.upstream = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)    # faces the rig
        self.upstream.bind(("127.0.0.1", 0))
        self.client = None
        self.held = {"up": None, "down": None}
        self.stall_until = 0.0
        self.counts = dict(forwarded=0, dropped=0, duplicated=0, corrupted=0, reordered=0)
        self._stop = False
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    @property
    def url(self) -> str:
        return f"udp://127.0.0.1:{self.port}"

    def stall(self, seconds: float) -> None:
        self.stall_until = time.perf_counter() + seconds

    def _send(self, direction: str, data: bytes) -> None:
        if direction == "up":
            self.upstream.sendto(data, self.rig)
        elif self.client is not None:
            self.sock.sendto(data, self.client)

    def _pass(self, direction: str, data: bytes) -> None:
        r, p, c = self.rng.random, self.p, self.counts
        if time.perf_counter() < self.stall_until or r() < p["drop"]:
            c["dropped"] += 1
            return
        if r() < p["corrupt"]:
            i = self.rng.randrange(len(data))
            data = data[:i] + bytes([data[i] ^ 0x5A]) + data[i + 1:]
            c["corrupted"] += 1
        if self.held[direction] is None and r() < p["reorder"]:
            self.held[direction] = data
            c["reordered"] += 1
            return
        self._send(direction, data)
        c["forwarded"] += 1
        if r() < p["duplicate"]:
            self._send(direction, data)
            c["duplicated"] += 1
        if self.held[direction] is not None:
            self._send(direction, self.held[direction])
            self.held[direction] = None

    def _run(self) -> None:
        while not self._stop:
            ready, _, _ = select.select([self.sock, self.upstream], [], [], 0.05)
            for s in ready:
                try:
                    data, addr = s.recvfrom(4096)
                except OSError:
                    continue
                if s is self.sock:
                    self.client = addr
                    self._pass("up", data)
                else:
                    self._pass("down", data)

    def close(self) -> None:
        self._stop = True
        self.thread.join(timeout=1)
        self.sock.close()
        self.upstream.close()
