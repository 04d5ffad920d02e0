"""The world's motion capture served as a VRPN server on loopback, as a motion-capture PC serves it.

One tracker per vehicle, named after it, streaming what the world's ``MocapModel`` delivers (its
rate, noise, latency and dropouts: a tracker whose body the model did not see in its latest frame
is left out of that cycle, as a real system leaves out a body it lost), so any VRPN client (the
stack's own, a real vrpn_client_ros, a user's script) reads the simulation as it would read a real
system. Port 3883 (the VRPN default) when it is free, else one the system picks; ``port`` says
which. Facts in docs/simulation.md ("Motion capture over VRPN").
"""
from __future__ import annotations

import socket
from typing import Optional, Tuple

from crazyflie_driver.mocap import vrpn_protocol as vp
from crazyflie_driver.mocap.vrpn_server import VrpnTestServer

LOOPBACK = "127.0.0.1"


def port_is_free(host: str, port: int) -> bool:
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        s.bind((host, port))
        return True
    except OSError:
        return False
    finally:
        s.close()


class WorldVrpnServer:
    """Serves a world's ``MocapModel`` frames over VRPN (start/stop; trackers follow the vehicles)."""

    def __init__(self, world, mocap, port: Optional[int] = None, host: str = LOOPBACK) -> None:
        self.world = world
        self.mocap = mocap
        if port is None:
            port = vp.DEFAULT_PORT if port_is_free(host, vp.DEFAULT_PORT) else 0
        self._server = VrpnTestServer(trackers=(), host=host, port=int(port), rate=float(mocap.rate))
        mocap.add_listener(self._on_frames)

    @property
    def port(self) -> int:
        return self._server.port

    @property
    def poses_sent(self) -> int:
        return self._server.poses_sent

    def sync_trackers(self) -> None:
        """One tracker per vehicle of the world (new vehicles get theirs; call after adding some)."""
        for v in self.world.vehicles():
            self._server.add_tracker(v.name)

    def start(self) -> Tuple[str, int]:
        self.sync_trackers()
        return self._server.start()

    def stop(self) -> None:
        self._server.stop()

    def __enter__(self) -> "WorldVrpnServer":
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def _on_frames(self, frames) -> None:
        """Each delivered frame sets its trackers' poses; bodies missing from it are not sent."""
        seen = set()
        for f in frames:
            self._server.add_tracker(f.name)
            self._server.set_pose(f.name, f.position, f.quaternion)
            self._server.hide(f.name, False)
            seen.add(f.name)
        for name in self._server.trackers:
            if name not in seen:
                self._server.hide(name, True)
