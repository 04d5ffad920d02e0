"""Which Crazyflies a script flies: Crazyswarm's ``crazyflies.yaml`` (or our swarm file), found
where Crazyswarm's scripts expect it, without ROS."""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import List, Optional, Sequence, Tuple

import yaml

from crazyflie_driver.errors import SwarmConfigError
from crazyflie_driver.server.swarm.config import parse_swarm

#: Where Crazyswarm's scripts find the file: the launch directory beside their scripts directory.
DEFAULT_YAML = os.path.join("..", "launch", "crazyflies.yaml")
#: Crazyswarm keeps the types beside the Crazyflies.
TYPES_FILE = "crazyflieTypes.yaml"


@dataclass(frozen=True)
class Entry:
    id: int
    initial_position: Tuple[float, float, float]
    tf_prefix: str


@dataclass(frozen=True)
class Source:
    text: str
    path: Optional[str]              # None: given as a YAML string

    @property
    def types_path(self) -> Optional[str]:
        """Crazyswarm's crazyflieTypes.yaml beside the file, if there is one."""
        if self.path is None:
            return None
        candidate = os.path.join(os.path.dirname(os.path.abspath(self.path)), TYPES_FILE)
        return candidate if os.path.isfile(candidate) else None


def find(crazyflies_yaml: Optional[str] = None, script_dir: Optional[str] = None) -> Source:
    """The YAML text and its path: ``crazyflies_yaml`` a path (ending in .yaml) or a YAML string;
    None: ``../launch/crazyflies.yaml`` from the working directory, else from the script's directory."""
    given = crazyflies_yaml if crazyflies_yaml is not None else DEFAULT_YAML
    if not given.strip().endswith(".yaml"):
        return Source(given, None)
    candidates = [given]
    if not os.path.isabs(given) and script_dir:
        candidates.append(os.path.join(script_dir, given))
    for path in candidates:
        if os.path.isfile(path):
            with open(path) as f:
                return Source(f.read(), os.path.abspath(path))
    raise SwarmConfigError("%s not found (looked at %s); pass Crazyswarm(crazyflies_yaml=...) a path or a YAML string, "
                           "or run the script from a directory whose ../launch/ holds crazyflies.yaml"
                           % (given, ", ".join(os.path.abspath(c) for c in candidates)))


def entries(source: Source) -> List[Entry]:
    """Each Crazyflie's id, initial position and ROS namespace (``tf_prefix``, default ``cf<id>``; in a
    Crazyswarm2 file the robot's name), of the enabled ones."""
    where = source.path or "<crazyflies yaml>"
    try:
        data = yaml.safe_load(source.text)
    except yaml.YAMLError as e:
        raise SwarmConfigError("%s: not valid YAML: %s" % (where, e)) from None
    if isinstance(data, dict) and "robots" in data:     # Crazyswarm2's format: the server's reader checks it
        return [Entry(cf.id, cf.initial_position, cf.tf_prefix)
                for cf in parse_swarm(source.text, where).crazyflies]
    if not isinstance(data, dict) or not isinstance(data.get("crazyflies"), list) or not data["crazyflies"]:
        raise SwarmConfigError("%s: needs a non-empty 'crazyflies' list of {id, channel, initialPosition, type}"
                               % where)
    out: List[Entry] = []
    for i, item in enumerate(data["crazyflies"]):
        if not isinstance(item, dict) or isinstance(item.get("id"), bool) or not isinstance(item.get("id"), int):
            raise SwarmConfigError("%s: crazyflies[%d] needs an integer 'id' (the radio address's last byte), got %r"
                                   % (where, i, item))
        pos = item.get("initialPosition", [0.0, 0.0, 0.0])
        if not _xyz(pos):
            raise SwarmConfigError("%s: crazyflies[%d] (id %d): initialPosition must be [x, y, z] in metres, got %r"
                                   % (where, i, item["id"], pos))
        prefix = str(item.get("tf_prefix", "cf%d" % item["id"])).strip("/")
        out.append(Entry(item["id"], tuple(float(v) for v in pos), prefix))
    ids = [e.id for e in out]
    if len(set(ids)) != len(ids):
        twice = sorted({i for i in ids if ids.count(i) > 1})
        raise SwarmConfigError("%s: ids %s appear more than once" % (where, twice))
    return out


def _xyz(value) -> bool:
    return (isinstance(value, (list, tuple)) and len(value) == 3
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value))


def script_dir(argv0: Sequence[str]) -> Optional[str]:
    """The directory of the running script (``sys.argv[0]``), if it is a file."""
    return os.path.dirname(os.path.abspath(argv0[0])) if argv0 and argv0[0] and os.path.isfile(argv0[0]) else None
