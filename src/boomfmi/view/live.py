"""The live feed: a running co-simulation sends its samples to ``boomfmi view --live``.

Each datagram is one UTF-8 JSON object, a flat sample in the run's column names
(``t``; the model's ``alpha, x, p_a, p_b``; the machine's ``alpha_measured,
x_measured, p_a_measured, p_b_measured``; ``f_est, f_ext, f_reflect``; gauge pressures
[Pa]) with the boom's geometry ``geom`` = [a, b, h, l_min] [m].  The sender keeps to
``rate`` datagrams per second of wall time, whatever the simulation's pace, and never
blocks: a view that is not running loses the datagrams, not the simulation's time.
"""
from __future__ import annotations

import json
import math
import socket
import time

from ..link.client import parse_address

#: the view's frame rate is capped by what the sender sends
DEFAULT_RATE = 60.0


class LiveSender:
    """``monitor`` for :meth:`CoSimulation.simulate`: picks the sample's columns from
    each recorded row and sends it to ``url`` (udp://HOST:PORT).

    ``columns`` maps a sample name to ``(column, offset)``: the value sent is
    ``row[column] + offset`` (the offset turns an absolute pressure into gauge)."""

    def __init__(self, url: str, columns: dict[str, tuple[str, float]], geom, rate: float = DEFAULT_RATE):
        if not rate > 0:
            raise ValueError(f"the live view's rate must be > 0 per second, not {rate!r}")
        self.address = parse_address(url)
        self.columns, self.geom, self.period = columns, [float(v) for v in geom], 1.0 / rate
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setblocking(False)
        self._index = None
        self._next = 0.0
        self.sent = 0

    def __call__(self, names: list[str], row) -> None:
        now = time.perf_counter()
        if now < self._next:
            return
        self._next = now + self.period
        if self._index is None:
            where = {n: i for i, n in enumerate(names)}
            self._index = {k: (where[c], off) for k, (c, off) in self.columns.items() if c in where}
        sample = {"t": float(row[0]), "geom": self.geom}
        for k, (i, off) in self._index.items():
            v = float(row[i]) + off
            sample[k] = v if math.isfinite(v) else None
        try:
            self.sock.sendto(json.dumps(sample).encode(), self.address)
            self.sent += 1
        except OSError:          # no view listening (yet): the run goes on
            pass

    def close(self) -> None:
        self.sock.close()
