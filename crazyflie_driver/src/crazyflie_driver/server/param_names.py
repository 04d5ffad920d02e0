"""The parameter names a service receives (``update_params``, per Crazyflie and swarm-wide), checked in one place.

A service gets ``group/name`` strings and reads each from the ROS parameter server before anything is
written to a Crazyflie. A name the firmware could never hold (a control character, a NUL, a space, no
group) is refused here by name, before it reaches the parameter server: its XML-RPC cannot carry a
control character and answers with a parse error instead of a reason. ROS-free: the node passes its
parameter-server lookup in.
"""
from __future__ import annotations

from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

from crazyflie_driver.errors import UnknownName
from crazyflie_driver.protocol.toc import check_toc_name

#: ``lookup(ros_name)``: the value of a ROS parameter, None when it is not set; raises when the parameter
#: server refuses the name.
Lookup = Callable[[str], Optional[Any]]


def ros_param_name(raw: Any) -> str:
    """``group/name`` (leading and trailing ``/`` ignored) -> ``group/name`` as checked by the firmware's TOC
    name rules (``protocol.toc.check_toc_name``). UnknownName naming the name and the rule."""
    if not isinstance(raw, str):
        raise UnknownName("%r: a parameter name is text of the form group/name" % (raw,))
    p = raw.strip("/")
    if p.count("/") != 1 or not all(p.split("/")):
        raise UnknownName("%r: not of the form group/name" % (raw,))
    group, name = p.split("/")
    try:
        check_toc_name("%s.%s" % (group, name), "parameter")
    except UnknownName as e:
        raise UnknownName("%r: %s" % (raw, e)) from None
    return p


def param_values(names: Sequence[Any], namespaces: Sequence[str], lookup: Lookup) -> Tuple[Dict[str, Any],
                                                                                             List[str]]:
    """The values an ``update_params`` call writes: each checked name (``ros_param_name``) read from the first
    of ``namespaces`` (``"/allcfs"``, ``"/cf1"``) where it is set. Returns ({"group.name": value}, errors,
    one per name that is malformed, set nowhere, or refused by the parameter server)."""
    values: Dict[str, Any] = {}
    errors: List[str] = []
    for raw in names:
        try:
            p = ros_param_name(raw)
        except UnknownName as e:
            errors.append(str(e))
            continue
        tried = []
        for ns in namespaces:
            ros_name = ns.rstrip("/") + "/" + p
            tried.append(ros_name)
            try:
                value = lookup(ros_name)
            except Exception as e:      # the parameter server's own refusal, named
                errors.append("%r: the ROS parameter server refused %s: %s" % (raw, ros_name, e))
                break
            if value is not None:
                values[p.replace("/", ".")] = value
                break
        else:
            errors.append("%r: ROS parameter %s is not set" % (raw, tried[0]) if len(tried) == 1 else
                          "%r: neither %s is set" % (raw, " nor ".join(tried)))
    return values, errors
