"""Work for many Crazyflies of a swarm, one lane per Crazyradio: the radios work in parallel.

A request to a Crazyflie (a parameter write, acknowledged) holds nothing but its own radio's round
trips, so writes to Crazyflies on different radios can all go at once. One shared pool taken in file
order does not do that: the first Crazyflies of a swarm file share a radio, so its first batch all
waits on one dongle while the others idle, and a slow radio holds up every later batch. Each lane
runs up to ``per_radio`` tasks at once (requests interleave on the dongle's FIFO); ROS-free.
"""
from __future__ import annotations

import threading
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Callable, Dict, List, Sequence, TypeVar

_T = TypeVar("_T")
_R = TypeVar("_R")


class RadioLanes:
    """Per radio index, a pool of ``per_radio`` threads; ``submit`` queues a task on its radio's lane."""

    def __init__(self, per_radio: int, name: str = "radio lane") -> None:
        if per_radio < 1:
            raise ValueError("per_radio must be >= 1, got %r" % (per_radio,))
        self.per_radio = per_radio
        self._name = name
        self._lock = threading.Lock()
        self._pools: Dict[int, ThreadPoolExecutor] = {}
        self._closed = False

    def submit(self, radio: int, fn: Callable[..., _R], *args) -> Future[_R]:
        with self._lock:
            if self._closed:
                raise RuntimeError("%s: shut down" % self._name)
            pool = self._pools.get(radio)
            if pool is None:
                pool = self._pools[radio] = ThreadPoolExecutor(
                    max_workers=self.per_radio, thread_name_prefix="%s %d" % (self._name, radio))
        return pool.submit(fn, *args)

    def map(self, radio_of: Callable[[_T], int], fn: Callable[[_T], _R], items: Sequence[_T]) -> List[_R]:
        """``fn(item)`` for every item on its radio's lane, the lanes at once; the results in ``items``' order
        (the first exception a task raised is raised once all have ended)."""
        futures = [self.submit(radio_of(item), fn, item) for item in items]
        errors = [f.exception() for f in futures]
        for e in errors:
            if e is not None:
                raise e
        return [f.result() for f in futures]

    def shutdown(self, wait: bool = True) -> None:
        with self._lock:
            self._closed = True
            pools, self._pools = list(self._pools.values()), {}
        for pool in pools:
            pool.shutdown(wait=wait)

    def __enter__(self) -> RadioLanes:
        return self

    def __exit__(self, *exc) -> None:
        self.shutdown(wait=True)
