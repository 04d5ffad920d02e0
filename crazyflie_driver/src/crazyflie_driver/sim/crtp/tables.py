"""The simulated firmware's variable tables: log variables, parameters, their C types and TOC CRC.

The current generation declares the real firmware's tables for a Crazyflie 2.1 build (about 400
parameters and 600 log variables, ids past 255; loaded by firmware_toc from the shipped data file)
with the defaults below where the firmware's are known and 0 elsewhere. The 2016.02 generation
keeps its small table (the groups users of the ROS stack touch, every C type a V1 host meets).
Entries carry the firmware generations they exist in.
"""
from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, replace
from typing import Dict, List, Optional, Sequence, Tuple, Union

from crazyflie_driver.crtp.ctypes import BY_LOG_CODE, CTYPES, CType
from crazyflie_driver.crtp.firmware_limits import TOC_NAME_MAX_BYTES
from crazyflie_driver.sim.crtp import firmware_toc

Number = Union[int, float]

GEN_CURRENT = "current"
GEN_2016 = "2016.02"
GENERATIONS = (GEN_CURRENT, GEN_2016)


#: The C types the simulated firmware declares its variables with (no 64-bit or double ones).
FIRMWARE_CTYPES = ("uint8_t", "uint16_t", "uint32_t", "int8_t", "int16_t", "int32_t", "float", "FP16")
LOG_TYPES: Dict[int, CType] = BY_LOG_CODE

PARAM_EXTENDED = 0x10
PARAM_CORE = 0x20
PARAM_RO = 0x40
PARAM_GROUP_START = 0x81
PARAM_GROUP_STOP = 0x80
EXTENDED_PERSISTENT = 0x01
LOG_GROUP_START = 0x81
LOG_GROUP_STOP = 0x80
LOG_CORE = 0x20           # in the TOC CRC only: TOC items carry the type's low nibble
LOG_BY_FUNCTION = 0x40


def convert(value: Number, ctype: CType) -> Number:
    """Value as a variable of ``ctype`` holds it: integers truncated toward zero and wrapped like a C
    cast, floats rounded to their width. Non-finite values become 0 for integer types."""
    if ctype.is_float:
        try:
            return ctype.unpack(ctype.pack(float(value)))
        except (OverflowError, struct.error):
            return float("inf") if float(value) > 0 else float("-inf")
    try:
        iv = int(value)
    except (OverflowError, ValueError):
        return 0
    bits = ctype.size * 8
    iv &= (1 << bits) - 1
    if ctype.signed and iv >= 1 << (bits - 1):
        iv -= 1 << bits
    return iv


def clamp(value: Number, ctype: CType) -> Number:
    """Value saturated to the range of ``ctype`` (how a physics reading lands in a firmware variable)."""
    if ctype.is_float:
        return convert(value, ctype)
    try:
        iv = int(value)
    except (OverflowError, ValueError):
        return 0
    return max(ctype.low, min(ctype.high, iv))


def pack(value: Number, ctype: CType) -> bytes:
    return ctype.pack(convert(value, ctype))


def unpack(data: bytes, ctype: CType) -> Number:
    return ctype.unpack(data[:ctype.size])


@dataclass(frozen=True)
class LogVar:
    group: str
    name: str
    ctype: str
    generations: Tuple[str, ...] = GENERATIONS
    core: bool = False                # LOG_ADD_CORE (current firmware's CRC only)
    by_function: bool = False         # computed on read (current firmware's CRC only)

    @property
    def full_name(self) -> str:
        return "%s.%s" % (self.group, self.name)

    def crc_type_byte(self, generation: str) -> int:
        """Type byte as the firmware's table holds it (the TOC CRC hashes it; TOC items carry the low nibble)."""
        code = CTYPES[self.ctype].log_code
        assert code is not None, "%s: C type %s cannot be logged" % (self.full_name, self.ctype)
        t = code
        if generation == GEN_CURRENT:
            t |= (LOG_CORE if self.core else 0) | (LOG_BY_FUNCTION if self.by_function else 0)
        return t


@dataclass(frozen=True)
class ParamVar:
    group: str
    name: str
    ctype: str
    default: Number = 0
    readonly: bool = False
    persistent: bool = False          # extended type: PERSISTENT (current firmware only)
    core: bool = False                # CORE flag (current firmware only)
    generations: Tuple[str, ...] = GENERATIONS

    @property
    def full_name(self) -> str:
        return "%s.%s" % (self.group, self.name)

    def type_byte(self, generation: str) -> int:
        t = CTYPES[self.ctype].param_code
        if self.readonly:
            t |= PARAM_RO
        if generation == GEN_CURRENT:
            if self.persistent:
                t |= PARAM_EXTENDED
            if self.core:
                t |= PARAM_CORE
        return t


_CUR = (GEN_CURRENT,)
_OLD = (GEN_2016,)


def _lv(group: str, names: str, ctype: str, gens: Tuple[str, ...] = GENERATIONS) -> List[LogVar]:
    return [LogVar(group, n, ctype, gens) for n in names.split()]


#: The small table of before the real-size one (2016.02 entries; its defaults seed the current table's).
_SMALL_LOG_TABLE: Tuple[LogVar, ...] = tuple(
    _lv("acc", "x y z", "float")
    + _lv("gyro", "x y z", "float")
    + _lv("gyro", "xRaw yRaw zRaw", "int16_t", _CUR)
    + _lv("mag", "x y z", "float")
    + _lv("mag_raw", "x y z", "int16_t", _OLD)
    + _lv("baro", "asl temp pressure", "float")
    + _lv("pm", "vbat", "float")
    + _lv("pm", "state", "int8_t")
    + _lv("pm", "batteryLevel", "uint8_t", _CUR)
    + _lv("stabilizer", "roll pitch yaw", "float")
    + _lv("stabilizer", "thrust", "float", _CUR)
    + _lv("stabilizer", "thrust", "uint16_t", _OLD)
    + _lv("stateEstimate", "x y z vx vy vz roll pitch yaw qx qy qz qw", "float", _CUR)
    + _lv("stateEstimateZ", "x y z vx vy vz", "int16_t", _CUR)
    + _lv("stateEstimateZ", "quat", "uint32_t", _CUR)
    + _lv("locSrv", "x y z qx qy qz qw", "float", _CUR)
    + _lv("locSrvZ", "tick", "uint16_t", _CUR)
    + _lv("ctrltarget", "x y z vx vy vz ax ay az", "float", _CUR)
    + _lv("posCtl", "targetVX targetVY targetVZ", "float", _CUR)
    + _lv("motor", "m1 m2 m3 m4", "uint16_t", _CUR)
    + _lv("motor", "m1 m2 m3 m4", "int32_t", _OLD)
    + _lv("radio", "rssi", "uint8_t")
    + _lv("radio", "isConnected", "uint8_t", _CUR)
    + _lv("radio", "numRxBc numRxUc", "uint16_t", _CUR)
    + _lv("sys", "canfly", "uint8_t")
    + _lv("sys", "isFlying isTumbled", "uint8_t", _CUR)
    + _lv("sys", "armed", "int8_t", _CUR)
    + _lv("supervisor", "info", "uint16_t", _CUR)
    + _lv("sys", "tick", "uint32_t")
)


def _pid(group: str, gains: Dict[str, Tuple[float, float, float]]) -> List[ParamVar]:
    out = []
    for axis, kpid in gains.items():
        for suffix, value in zip(("kp", "ki", "kd"), kpid):
            out.append(ParamVar(group, "%s_%s" % (axis, suffix), "float", value))
    return out


# Defaults of the current firmware (docs/simulation.md, "The onboard attitude and rate controllers"); the world
# overrides them per generation.
_SMALL_PARAM_TABLE: Tuple[ParamVar, ...] = tuple(
    [ParamVar("sound", "effect", "uint8_t", 0), ParamVar("sound", "neffect", "uint32_t", 14, readonly=True),
     ParamVar("sound", "freq", "uint16_t", 4000)]
    + [ParamVar("ring", "effect", "uint8_t", 6, persistent=True),
       ParamVar("ring", "neffect", "uint32_t", 20, readonly=True),
       ParamVar("ring", "solidRed", "uint8_t", 20), ParamVar("ring", "solidGreen", "uint8_t", 20),
       ParamVar("ring", "solidBlue", "uint8_t", 20),
       ParamVar("ring", "headlightEnable", "uint8_t", 0),
       ParamVar("ring", "emptyCharge", "float", 3.1), ParamVar("ring", "fullCharge", "float", 4.2),
       ParamVar("ring", "glowstep", "int16_t", 1)]
    + [ParamVar("commander", "enHighLevel", "uint8_t", 0, core=True, generations=_CUR)]
    + [ParamVar("flightmode", "althold", "uint8_t", 0, generations=_OLD)]
    + [ParamVar("flightmode", "stabModeRoll", "uint8_t", 1), ParamVar("flightmode", "stabModePitch", "uint8_t", 1),
       ParamVar("flightmode", "stabModeYaw", "uint8_t", 0)]
    + _pid("pid_attitude", {"roll": (6.0, 3.0, 0.0), "pitch": (6.0, 3.0, 0.0), "yaw": (6.0, 1.0, 0.35)})
    + _pid("pid_rate", {"roll": (250.0, 500.0, 2.5), "pitch": (250.0, 500.0, 2.5), "yaw": (120.0, 16.7, 0.0)})
    + [ParamVar("stabilizer", "estimator", "uint8_t", 1, core=True, generations=_CUR),
       ParamVar("stabilizer", "controller", "uint8_t", 1, core=True, generations=_CUR),
       ParamVar("stabilizer", "stop", "uint8_t", 0, generations=_CUR)]
    + [ParamVar("motorPowerSet", "enable", "uint8_t", 0)]
    + [ParamVar("motorPowerSet", "m%d" % i, "uint16_t", 0) for i in range(1, 5)]
    + [ParamVar("system", "selftestPassed", "int8_t", 1, readonly=True, generations=_CUR),
       ParamVar("system", "taskDump", "uint8_t", 0, generations=_CUR),
       ParamVar("system", "forceArm", "int8_t", 0, generations=_CUR)]
    + [ParamVar("health", "startPropTest", "uint8_t", 0, generations=_CUR)]
    + [ParamVar("kalman", "resetEstimation", "uint8_t", 0, generations=_CUR),
       ParamVar("kalman", "pNAcc_xy", "float", 0.5, generations=_CUR),
       ParamVar("kalman", "pNAcc_z", "float", 1.0, generations=_CUR)]
    + [ParamVar("kalman", n, "float", 0.0, generations=_CUR)
       for n in ("initialX", "initialY", "initialZ", "initialYaw")]
    + [ParamVar("kalman", "maxPos", "float", 100.0, generations=_CUR),
       ParamVar("kalman", "maxVel", "float", 10.0, generations=_CUR)]
    + [ParamVar("hlCommander", "groupmask", "uint8_t", 0, generations=_CUR),
       ParamVar("hlCommander", "vtoff", "float", 0.5, generations=_CUR),
       ParamVar("hlCommander", "vland", "float", 0.5, generations=_CUR)]
    + [ParamVar("ctrlMel", n, "float", 0.0, generations=_CUR)
       for n in ("kp_xy", "kd_xy", "ki_xy", "i_range_xy", "kp_z", "kd_z", "ki_z", "i_range_z", "mass", "massThrust",
                 "kR_xy", "kw_xy", "ki_m_xy", "i_range_m_xy", "kR_z", "kw_z", "ki_m_z", "i_range_m_z",
                 "kd_omega_rp")]
    + [ParamVar("locSrv", "extPosStdDev", "float", 0.01, generations=_CUR),
       ParamVar("locSrv", "extQuatStdDev", "float", 4.5e-3, generations=_CUR)]
    # onboard estimator and position controller: the world's vehicle supplies the firmware's defaults
    + [ParamVar("posCtlPid", "%s%s" % (axis, term), "float", 0.0, persistent=True, generations=_CUR)
       for axis in "xyz" for term in ("Kp", "Ki", "Kd", "Kff")]
    + [ParamVar("posCtlPid", "thrustBase", "uint16_t", 36000, persistent=True, generations=_CUR),
       ParamVar("posCtlPid", "thrustMin", "uint16_t", 20000, persistent=True, generations=_CUR)]
    + [ParamVar("posCtlPid", n, "float", 0.0, persistent=True, generations=_CUR)
       for n in ("rLimit", "pLimit", "xVelMax", "yVelMax", "zVelMax")]
    + [ParamVar("velCtlPid", "%s%s" % (axis, term), "float", 0.0, persistent=True, generations=_CUR)
       for axis in ("vx", "vy", "vz") for term in ("Kp", "Ki", "Kd", "KFF")]
    + [ParamVar("imu_tests", "MPU6500", "uint8_t", 1, readonly=True, generations=_OLD),
       ParamVar("imu_sensors", "AK8963", "uint8_t", 1, readonly=True),
       ParamVar("imu_sensors", "LPS25H", "uint8_t", 1, readonly=True)]
    + [ParamVar("cpu", "flash", "uint16_t", 1024, readonly=True),
       ParamVar("cpu", "id0", "uint32_t", 0x00320024, readonly=True),
       ParamVar("cpu", "id1", "uint32_t", 0x3435470D, readonly=True),
       ParamVar("cpu", "id2", "uint32_t", 0x37323731, readonly=True)]
    + [ParamVar("firmware", "revision0", "uint32_t", 0x2A18FC29, readonly=True),
       ParamVar("firmware", "revision1", "uint16_t", 0, readonly=True),
       ParamVar("firmware", "modified", "uint8_t", 0, readonly=True)]
    + [ParamVar("lighthouse", "systemType", "int32_t", 2, generations=_CUR)]
)

#: Known defaults of the current firmware's parameters the small table lacks (firmware source).
FIRMWARE_DEFAULTS: Dict[str, Number] = {
    "lighthouse.systemType": 2, "powerDist.idleThrust": 0, "pid_attitude.attFiltEn": 0, "pid_rate.rateFiltEn": 0,
    "ring.fadeTime": 0.5, "kalman.robustTdoa": 0, "kalman.robustTwr": 0, "colAv.enable": 0,
    "supervisor.tmblChckEn": 1, "pm.lowVoltage": 3.2, "pm.criticalLowVoltage": 3.0,
}
#: Parameters the firmware's build generates (src/utils/src/version.tmpl), absent from the source table.
GENERATED_PARAMS: Tuple[ParamVar, ...] = (
    ParamVar("firmware", "revision0", "uint32_t", 0x2A18FC29, readonly=True, core=True, generations=_CUR),
    ParamVar("firmware", "revision1", "uint16_t", 0, readonly=True, core=True, generations=_CUR),
    ParamVar("firmware", "modified", "uint8_t", 0, readonly=True, core=True, generations=_CUR),
)


def real_params(rows: Sequence[firmware_toc.TocRow], defaults: Dict[str, Number],
                generations: Tuple[str, ...] = _CUR) -> List[ParamVar]:
    """Parameter entries of the firmware's rows; ``defaults`` by full name, 0 for names it lacks."""
    out = []
    for r in firmware_toc.first_of_each_name(x for x in rows if x.kind == "param"):
        full = "%s.%s" % (r.group, r.name)
        out.append(ParamVar(r.group, r.name, r.ctype, defaults.get(full, 0),
                            readonly="PARAM_RONLY" in r.flags, persistent="PARAM_PERSISTENT" in r.flags,
                            core=r.macro == "core", generations=generations))
    return out


def real_logs(rows: Sequence[firmware_toc.TocRow], generations: Tuple[str, ...] = _CUR) -> List[LogVar]:
    """Log entries of the firmware's rows (values come from the vehicle by name at run time)."""
    return [LogVar(r.group, r.name, r.ctype, generations, core=r.macro == "core", by_function=r.macro == "by_function")
            for r in firmware_toc.first_of_each_name(x for x in rows if x.kind == "log")]


def _defaults_of(table: Sequence[ParamVar]) -> Dict[str, Number]:
    out: Dict[str, Number] = {e.full_name: e.default for e in table}
    out.update(FIRMWARE_DEFAULTS)
    return out


def _only(table: Sequence, generation: str) -> list:
    """Entries of ``table`` restricted to ``generation`` (and marked as existing only there)."""
    return [replace(e, generations=(generation,)) for e in table if generation in e.generations]


_FIRMWARE_ROWS = firmware_toc.load()
#: Log variables of both generations: the real firmware's (current) and the small table (2016.02).
LOG_TABLE: Tuple[LogVar, ...] = tuple(real_logs(_FIRMWARE_ROWS) + _only(_SMALL_LOG_TABLE, GEN_2016))
#: Parameters of both generations: the real firmware's plus its generated ones (current), the small table (2016.02).
PARAM_TABLE: Tuple[ParamVar, ...] = tuple(real_params(_FIRMWARE_ROWS, _defaults_of(_SMALL_PARAM_TABLE))
                                          + list(GENERATED_PARAMS) + _only(_SMALL_PARAM_TABLE, GEN_2016))


def select(table: Sequence, generation: str) -> list:
    """Entries of a table that exist in ``generation``, grouped as the linker lays them out (first
    appearance of a group decides its position; order inside a group is kept)."""
    entries = [e for e in table if generation in e.generations]
    groups: Dict[str, list] = {}
    for e in entries:
        groups.setdefault(e.group, []).append(e)
    return [e for members in groups.values() for e in members]


def toc_crc(entries: Sequence, type_byte) -> int:
    """Chained CRC32 over the raw table including group start/stop markers (docs/protocol.md, "Port 2 (parameters)"):
    crc_i = CRC32(LE32(crc_{i-1}) + type byte + name)."""
    crc = 0
    last_group: Optional[str] = None

    def step(t: int, name: str) -> None:
        nonlocal crc
        crc = zlib.crc32(struct.pack("<I", crc) + bytes([t]) + name.encode("ascii")) & 0xFFFFFFFF

    for e in entries:
        if e.group != last_group:
            if last_group is not None:
                step(PARAM_GROUP_STOP, "stop_" + last_group)
            step(PARAM_GROUP_START, e.group)
            last_group = e.group
        step(type_byte(e), e.name)
    if last_group is not None:
        step(PARAM_GROUP_STOP, "stop_" + last_group)
    return crc


def toc_item_name(entry) -> bytes:
    """``group NUL name NUL`` as TOC items carry them."""
    return entry.group.encode("ascii") + b"\x00" + entry.name.encode("ascii") + b"\x00"


def check_names(entries: Sequence) -> None:
    """The firmware asserts strlen(group)+strlen(name)+2 <= TOC_NAME_MAX_BYTES at boot; so do we."""
    for e in entries:
        if len(e.group) + len(e.name) + 2 > TOC_NAME_MAX_BYTES:
            raise ValueError("TOC entry %s.%s: group+name longer than the firmware allows (%d chars)"
                             % (e.group, e.name, TOC_NAME_MAX_BYTES - 2))
        if e.ctype not in FIRMWARE_CTYPES:
            raise ValueError("TOC entry %s.%s: unknown C type %r" % (e.group, e.name, e.ctype))
