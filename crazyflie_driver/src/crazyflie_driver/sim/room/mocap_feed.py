"""A simulator extension: the world's motion capture fed straight into chosen vehicles' onboard estimators.

A real Crazyflie learns its position from a host that streams motion capture to it (port 6). Users who
fly the simulation with cflib alone can switch this on per vehicle instead (CrazySim offers the same):
every frame the ``MocapModel`` delivers for that vehicle, with the model's rate, noise, latency and
dropouts, reaches its estimator as an external pose would. Off by default; it has no counterpart in
the firmware, so nothing on the radio changes (docs/simulation.md, "Motion capture into the estimator").
"""
from __future__ import annotations

from typing import Callable, FrozenSet, List, Optional

import numpy as np

Deliver = Callable[[str, np.ndarray, np.ndarray], None]      # (vehicle name, position m, quaternion xyzw)


class MocapEstimatorFeed:
    """The per-vehicle switch and the listener that forwards a mocap model's frames."""

    def __init__(self, deliver: Deliver) -> None:
        self._deliver = deliver
        self._names: FrozenSet[str] = frozenset()        # replaced whole: the stepping thread reads it
        self._model = None

    @property
    def model(self):
        return self._model

    def attach(self, model) -> None:
        """Feed from ``model`` (a ``MocapModel``) from now on; an earlier model stops feeding."""
        self._model = model
        model.add_listener(lambda frames: self._on_frames(model, frames))

    def set(self, name: str, on: bool) -> None:
        self._names = self._names | {name} if on else self._names - {name}

    def enabled(self, name: str) -> bool:
        return name in self._names

    def names(self) -> List[str]:
        return sorted(self._names)

    def _on_frames(self, model, frames) -> None:
        names: Optional[FrozenSet[str]] = self._names
        if model is not self._model or not names:
            return
        for f in frames:
            if f.name in names:
                self._deliver(f.name, f.position, f.quaternion)
