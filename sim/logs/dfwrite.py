"""A DataFlash (`.bin`) writer: ArduPilot's log format as pymavlink's DFReader reads it (each message
0xA3 0x95, its type, its fields packed little-endian; FMT messages define the types), so that a flight
of this project's simulator can be written as an ArduCopter log and read back (the tests, and the
simulated fleet of sim/sweeps/fleet_flown.py). The field layouts are ArduPilot's own (its LogStructure.h);
GPS as ArduPilot 4.x logs it: GMS the GPS time of week (ms), GWk the GPS week, Lat/Lng 1e-7 degrees."""
from __future__ import annotations

import struct

HEAD = b"\xa3\x95"
CODES = {"B": "B", "H": "H", "I": "I", "f": "f", "Q": "Q", "n": "4s", "N": "16s", "Z": "64s", "L": "i"}
FORMATS = {  # name: (type id, format, columns)
    "PARM": (129, "QNf", "TimeUS,Name,Value"),
    "MSG": (130, "QZ", "TimeUS,Message"),
    "IMU": (131, "QBffffff", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ"),
    "RCOU": (132, "Q" + "H" * 14, "TimeUS," + ",".join(f"C{i}" for i in range(1, 15))),
    "BAT": (133, "QBff", "TimeUS,Inst,Volt,Curr"),
    "ATT": (134, "Qffffff", "TimeUS,DesRoll,Roll,DesPitch,Pitch,DesYaw,Yaw"),
    "RATE": (135, "Qfff", "TimeUS,RDes,PDes,YDes"),
    "ESC": (136, "QBf", "TimeUS,Instance,RPM"),
    "ARM": (137, "QB", "TimeUS,ArmState"),
    "BARO": (138, "QBf", "TimeUS,I,Alt"),
    "VIBE": (139, "QfffIII", "TimeUS,VibeX,VibeY,VibeZ,Clip0,Clip1,Clip2"),   # ArduCopter 3.3-4.0's
    "GPS": (140, "QBBIHBfLLffff", "TimeUS,I,Status,GMS,GWk,NSats,HDop,Lat,Lng,Alt,Spd,GCrs,VZ"),
    # the rate PIDs' first fields as ArduCopter 4.x logs them (rad/s; the rest of its PID layout left out)
    "PIDR": (141, "Qfffffff", "TimeUS,Tar,Act,Err,P,I,D,FF"),
    "PIDP": (142, "Qfffffff", "TimeUS,Tar,Act,Err,P,I,D,FF"),
    "PIDY": (143, "Qfffffff", "TimeUS,Tar,Act,Err,P,I,D,FF"),
    "EV": (144, "QB", "TimeUS,Id"),
}


def _pack(fmt: str, values) -> bytes:
    out = []
    for code, v in zip(fmt, values):
        out.append(v.encode() if isinstance(v, str) else v)
    return struct.pack("<" + "".join(CODES[c] for c in fmt), *out)


class DataFlash:
    """A log being written. `without`: message types left out, as ArduPilot's logger leaves out what
    LOG_BITMASK does not ask for (IMU without bit 7): no FMT for them, and `add` of one writes nothing."""

    def __init__(self, without: tuple[str, ...] = ()):
        self.buf = bytearray()
        self.without = set(without)
        fmt = (128, "BBnNZ", "Type,Length,Name,Format,Columns")
        self._fmt("FMT", *fmt)
        for name, (tid, f, cols) in FORMATS.items():
            if name not in self.without:
                self._fmt(name, tid, f, cols)

    def _fmt(self, name, tid, f, cols):
        length = 3 + struct.calcsize("<" + "".join(CODES[c] for c in f))
        self.buf += HEAD + bytes([128]) + _pack("BBnNZ", (tid, length, name, f, cols))

    def add(self, name: str, *values) -> None:
        if name in self.without:
            return
        tid, f, _ = FORMATS[name]
        self.buf += HEAD + bytes([tid]) + _pack(f, values)

    def bytes(self) -> bytes:
        return bytes(self.buf)


# ArduCopter 3.1's messages as its text dump writes them (Log.pde): MOT and ATT carry no time stamp
FORMATS_31 = {"PARM": (129, "Nf", "Name,Value"), "IMU": (131, "Iffffff", "TimeMS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ"),
              "MSG": (132, "Z", "Message"), "CURR": (9, "hIhhhf", "ThrOut,ThrInt,Volt,Curr,Vcc,CurrTot"),
              "MOT": (11, "hhhh", "Mot1,Mot2,Mot3,Mot4"), "EV": (13, "B", "Id")}
SIZES = {"B": 1, "h": 2, "H": 2, "I": 4, "f": 4, "c": 2, "C": 2, "N": 16, "Z": 64}


def text_log(header: list[str], rows: list[tuple]) -> str:
    """An ArduCopter 3.1 text dump: the header lines its CLI writes before the formats, the FMT lines,
    then one line per (name, values...) of `rows`."""
    lines = header + ["FMT, 128, 89, FMT, BBnNZ, Type,Length,Name,Format"]
    lines += [f"FMT, {tid}, {3 + sum(SIZES[c] for c in f)}, {name}, {f}, {cols}" for name, (tid, f, cols) in FORMATS_31.items()]
    lines += [", ".join([name] + [str(v) for v in values]) for name, *values in rows]
    return "\r\n".join(lines) + "\r\n"
