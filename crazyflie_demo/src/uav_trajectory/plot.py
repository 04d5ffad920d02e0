"""A trajectory file at a glance: the path from above and from the side, and position, velocity,
acceleration, body rates and yaw over time, written to a PNG (matplotlib, no display needed)."""
from __future__ import annotations

from typing import Optional

import numpy as np

from uav_trajectory import Trajectory

SAMPLES_PER_S = 100


def plot(trajectory: Trajectory, out_png: str, title: Optional[str] = None) -> str:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = max(2, int(trajectory.duration * SAMPLES_PER_S) + 1)
    ts = np.linspace(0.0, trajectory.duration, n)
    states = [trajectory.eval(t) for t in ts]
    series = {name: np.array([getattr(s, name) for s in states]) for name in ("pos", "vel", "acc", "omega", "yaw")}
    speed = np.linalg.norm(series["vel"], axis=1)

    fig = plt.figure(figsize=(12, 9))
    grid = fig.add_gridspec(3, 3)
    top = fig.add_subplot(grid[0:2, 0])
    top.plot(series["pos"][:, 0], series["pos"][:, 1])
    top.plot(series["pos"][0, 0], series["pos"][0, 1], "go", label="start")
    top.plot(series["pos"][-1, 0], series["pos"][-1, 1], "rx", label="end")
    top.set_xlabel("x [m]"), top.set_ylabel("y [m]"), top.set_aspect("equal", adjustable="datalim")
    top.set_title("from above"), top.legend(loc="best")
    side = fig.add_subplot(grid[2, 0])
    side.plot(series["pos"][:, 0], series["pos"][:, 2])
    side.set_xlabel("x [m]"), side.set_ylabel("z [m]"), side.set_title("from the side")
    panels = [("pos", "position [m]"), ("vel", "velocity [m/s]"), ("acc", "acceleration [m/s²]"),
              ("omega", "body rates [rad/s]")]
    for i, (key, label) in enumerate(panels):
        ax = fig.add_subplot(grid[i // 2, 1 + i % 2])
        for k, axis in enumerate("xyz"):
            ax.plot(ts, series[key][:, k], label=axis)
        if key == "vel":
            ax.plot(ts, speed, "k--", label="speed")
        ax.set_ylabel(label), ax.legend(loc="best", fontsize="small")
    ax = fig.add_subplot(grid[2, 1:])
    ax.plot(ts, series["yaw"])
    ax.set_xlabel("t [s]"), ax.set_ylabel("yaw [rad]")
    fig.suptitle(title or "%d pieces, %.2f s; top speed %.2f m/s, mean %.2f m/s"
                 % (trajectory.n_pieces(), trajectory.duration, speed.max(), speed.mean()))
    fig.tight_layout()
    fig.savefig(out_png, dpi=90)
    plt.close(fig)
    return out_png
