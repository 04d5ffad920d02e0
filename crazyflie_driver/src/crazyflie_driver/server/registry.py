"""The Crazyflies one server process serves, keyed by canonical URI.

``/add_crazyflie`` and ``/remove_crazyflie`` come in on service threads, possibly at once: the
registry refuses a URI or tf_prefix already served, reserves the URI while its worker connects
(so a slow or absent Crazyflie blocks only its own caller), and keeps nothing when the connect
fails or times out: the worker is stopped and its link closed before the slot is freed and the
caller hears of it, so nothing more goes to that Crazyflie and an add again finds it free.
"""
from __future__ import annotations

import threading
from typing import Any, Callable, Dict, List, Optional

from crazyflie_driver.crtp.uri import parse_link_uri
from crazyflie_driver.server.log_plan import validate_log_block_specs
from crazyflie_driver.server.worker import CrazyflieWorker, WorkerConfig, WorkerListener

#: s a failed add waits for its worker's connect sequence to end once the link is closed under it (one
#: radio round trip in practice; a thread still busy after this is left to finish and close the link)
ADD_TEARDOWN_S = 5.0


class DuplicateCrazyflie(ValueError):
    """A URI (or tf_prefix) that the server already serves."""


class CrazyflieRegistry:
    """The Crazyflies of one server, by canonical URI. ``add`` blocks only the caller."""

    def __init__(self, crazyflie_factory: Callable[[str], Any],
                 worker_options: Optional[Dict[str, Any]] = None) -> None:
        self._factory = crazyflie_factory
        self._options = dict(worker_options or {})
        self._lock = threading.Lock()
        self._workers: Dict[str, CrazyflieWorker] = {}

    @staticmethod
    def canonical_uri(uri: str) -> str:
        return str(parse_link_uri(uri))

    def check_free(self, config: WorkerConfig) -> None:
        """DuplicateCrazyflie when ``config``'s URI or tf_prefix is already served; callers ask before
        they build anything for it (``add`` asks again under its lock)."""
        with self._lock:
            self._check_free(self.canonical_uri(config.uri), config.tf_prefix)

    def _check_free(self, key: str, tf_prefix: str) -> None:
        if key in self._workers:
            raise DuplicateCrazyflie("Crazyflie %s is already served as %r"
                                     % (key, self._workers[key].config.tf_prefix))
        for w in self._workers.values():
            if w.config.tf_prefix == tf_prefix:
                raise DuplicateCrazyflie("tf_prefix %r is already served by %s" % (tf_prefix, w.uri))

    def add(self, config: WorkerConfig, listener: Optional[WorkerListener] = None,
            timeout: float = 20.0) -> CrazyflieWorker:
        """Connect a Crazyflie and start serving it; raises a clear error and keeps nothing on failure."""
        key = self.canonical_uri(config.uri)
        validate_log_block_specs(config.log_blocks)
        with self._lock:
            self._check_free(key, config.tf_prefix)
            cf = self._factory(config.uri)
            worker = CrazyflieWorker(config, cf, listener, **self._options)
            self._workers[key] = worker      # reserve the URI while connecting
        try:
            worker.start()
            worker.wait_ready(timeout)
        except BaseException:
            worker.stop(timeout=ADD_TEARDOWN_S)     # cuts a connect under way short: nothing more is sent
            with self._lock:
                if self._workers.get(key) is worker:
                    del self._workers[key]
            raise
        return worker

    def remove(self, uri: str, timeout: float = 2.0) -> None:
        key = self.canonical_uri(uri)
        with self._lock:
            worker = self._workers.pop(key, None)
        if worker is None:
            raise KeyError("Crazyflie %s is not added" % key)
        worker.stop(timeout)

    def get(self, uri: str) -> CrazyflieWorker:
        key = self.canonical_uri(uri)
        with self._lock:
            if key not in self._workers:
                raise KeyError("Crazyflie %s is not added" % key)
            return self._workers[key]

    def workers(self) -> List[CrazyflieWorker]:
        with self._lock:
            return list(self._workers.values())

    def shutdown(self, timeout: float = 2.0) -> None:
        with self._lock:
            workers = list(self._workers.values())
            self._workers.clear()
        for w in workers:
            w.stop(timeout)
