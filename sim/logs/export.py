"""`flightctl log export FLIGHT.csv FLIGHT.ulg`: a flight log as PX4's ULog, for PlotJuggler and
Flight Review (the format: https://docs.px4.io/main/en/dev_log/ulog_file_format.html), which `flightctl
log import` and `flightctl diagnose` read back as the flight log it was written from (own.py).

The file: the 16-byte header, the flag bits, then the definitions (formats, information messages
with the software version, every parameter, subscriptions) and the data messages in time order.
Topics take PX4's names and fields (PX4-Autopilot's msg/*.msg), so the tools that know PX4 plot them,
and PX4's frames: body FRD, inertial NED, converted once here (flightctl/comms/frames.py). Timestamps
are microseconds since the loop started (the log's time plus its calibration time).

| topic | fields | from the CSV |
|---|---|---|
| sensor_combined | gyro_rad[3] (rad/s), accelerometer_m_s2[3] (m/s^2) | gyro_*, acc_* |
| vehicle_attitude | q[4] (FRD to NED) | roll, pitch, yaw (the estimate) |
| vehicle_attitude_setpoint | roll_body, pitch_body, yaw_body (rad; PX4 before 1.14), q_d[4] | *_sp |
| vehicle_local_position | z (m, down), dist_bottom (m) | alt (the estimate) |
| vehicle_local_position_setpoint | z (m, down) | alt_sp |
| actuator_outputs | noutputs, output[4] (ESC pulse, us) | P1..P4 |
| actuator_motors | control[4] (P / 255: PX4's normalised motor commands) | P1..P4 |
| vehicle_angular_velocity | xyz[3] (rad/s, FRD) | gyro_* |
| vehicle_rates_setpoint | roll, pitch, yaw (rad/s, FRD), thrust_body[3] | setpoint_* where logged, else the rate the PD commands: kp/kd times the angle error (eq. 24 as an angle loop feeding a rate loop, the integral left out); thrust: -mean P / 255 on z |
| vehicle_status | arming_state (2 armed: the log starts at arming), nav_state (3, a mission: a plan), vehicle_type (1, rotary wing), is_vtol | one sample a second |
| input_rc | channel_count, rssi, values[18] (us) | rc_* where logged (an imported log): 1500 + 500 stick, throttle 1000 + 1000 |
| battery_status | voltage_v, voltage_filtered_v (V), current_a (A, -1 unknown) | battery_v, current (rows with a reading) |
| distance_sensor | current_distance, min_distance, max_distance (m), orientation, type | range (rows with an echo) |
| vehicle_magnetometer | magnetometer_ga[3] (Gauss, FRD) | mag_* (T; rows with a reading) |
| vehicle_attitude_groundtruth, vehicle_local_position_groundtruth | q[4]; x, y, z (m) | true_* (simulator only) |
| flightctl_log | one float a column, as the CSV has it | roll, pitch, yaw, roll_sp, pitch_sp, yaw_sp, true_roll, true_pitch, true_yaw and every other column without a PX4 field that holds it (the sticks: input_rc holds whole us; own.py) |

The vehicle is described the PX4 way, so that PX4 tools read it: MAV_TYPE 2, CA_ROTOR_COUNT 4 and
CA_ROTOR{0..3}_PX/PY/KM (the paper's + layout, eq. 25, FRD, KM > 0 counter-clockwise),
PWM_MAIN_FUNC1..4 = 101..104 with PWM_MAIN_MIN/MAX the pulse of P = 0 and 255. The log's `# params:`
file is flattened (`kp_z` is `gains.kp_z`) into float parameters named as PX4 allows (at most 16
characters: `FC_` and the section's letter, `FC_G_KP_Z`; a longer name keeps its first 12 characters
and a 3-character hash), and the `flightctl_params` information message lists `SHORT=full.name` for
each. A log whose header has `# vehicle_id:` and `# start_utc:` (sim/sweeps/fleet_flown.py) gets them as
PX4 has them: the `sys_uuid` information message, and vehicle_gps_position's `time_utc_usec` once a
second. The information messages `sys_name` flightctl, `flightctl_columns` (the CSV's columns),
`flightctl_meta` (its `# key: value` lines, JSON) and `flightctl_t0_us` make it flightctl's own.
"""
from __future__ import annotations

import datetime
import hashlib
import json
import re
import struct
import sys
import tomllib
from pathlib import Path

import numpy as np

from flightctl import __version__
from flightctl.errors import InputError, Parser
from flightctl.files import output_file, write_atomic
from flightctl.comms.frames import euler_ned, pulse_us, quaternion, vector_ned
from flightctl.logfile import FLIGHT_COLUMNS, MAG_COLUMNS, read_flight_log
from flightctl.params import Airframe, Gains, from_dict
from flightctl.sim.logs.own import HOMES, NAME, OWN_TOPIC, SPARSE, own_columns

MAGIC = b"ULog\x01\x12\x35"
FILE_VERSION = 1
ULTRASOUND, DOWNWARD = 1, 25          # PX4's distance_sensor type and orientation (ROTATION_DOWNWARD_FACING)
SONAR_RANGE_M = (0.02, 4.0)           # HC-SR04
TRUTH = ("true_x", "true_y", "true_z", "true_roll", "true_pitch", "true_yaw")

# numpy field type of each ULog type
_TYPES = {"uint64_t": "<u8", "uint32_t": "<u4", "int32_t": "<i4", "uint16_t": "<u2", "uint8_t": "u1",
          "bool": "u1", "float": "<f4"}
PARAM_CHARS = 16                      # PX4's limit on a parameter's name
ARMED, AUTO_MISSION, ROTARY_WING = 2, 3, 1     # vehicle_status.arming_state, nav_state, vehicle_type


def _message(kind: str, payload: bytes) -> bytes:
    """One ULog message: uint16 payload size, uint8 type, the payload."""
    if len(payload) > 0xFFFF:
        raise ValueError(f"ULog message {kind!r} too long ({len(payload)} bytes)")
    return struct.pack("<HB", len(payload), ord(kind)) + payload


def _info(key: str, value) -> bytes:
    """An 'I' message; `value` str -> char[n], int -> uint32_t."""
    if isinstance(value, str):
        raw = value.encode()
        tkey = f"char[{len(raw)}] {key}".encode()
    else:
        raw, tkey = struct.pack("<I", value), f"uint32_t {key}".encode()
    return _message("I", bytes([len(tkey)]) + tkey + raw)


def _parameter(name: str, value: float) -> bytes:
    """A 'P' message: a float, or an int32_t for an int (PX4's integer parameters)."""
    if isinstance(value, int):
        tkey, raw = f"int32_t {name}".encode(), struct.pack("<i", value)
    else:
        tkey, raw = f"float {name}".encode(), struct.pack("<f", value)
    return _message("P", bytes([len(tkey)]) + tkey + raw)


def short_name(name: str) -> str:
    """A flattened parameter's name as PX4 allows it (at most 16 characters, upper case):
    `gains.kp_z` -> `FC_G_KP_Z`; a longer one keeps its first 12 characters and a 3-character hash."""
    section, _, rest = name.rpartition(".")
    head = {"": "FC_", "gains": "FC_G_", "filters": "FC_F_"}.get(section)
    if head is None:                                   # effect{k}.{cause}.{name}
        head = "FC_E" + section.split(".")[0].removeprefix("effect") + "_"
    short = (head + rest).upper()
    if len(short) > PARAM_CHARS:
        digest = int.from_bytes(hashlib.sha1(name.encode()).digest()[:4], "big")
        code = "".join("0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZ"[(digest // 36 ** k) % 36] for k in range(3))
        short = short[:PARAM_CHARS - 4] + "_" + code
    return short


class Topic:
    """A topic's format and its data messages as one structured array (header included), so that a
    long log is packed by numpy, not row by row."""

    def __init__(self, name: str, fields: list[tuple[str, str, int]]):
        self.name, self.fields = name, [("uint64_t", "timestamp", 0)] + fields
        dtype = [("size", "<u2"), ("kind", "u1"), ("msg_id", "<u2")]
        for ftype, fname, n in self.fields:
            dtype.append((fname, _TYPES[ftype], (n,)) if n else (fname, _TYPES[ftype]))
        self.dtype = np.dtype(dtype)   # packed (numpy aligns nothing unless asked), as ULog is

    def format(self) -> bytes:
        text = ";".join(f"{t}[{n}] {f}" if n else f"{t} {f}" for t, f, n in self.fields)
        return _message("F", f"{self.name}:{text};".encode())

    def records(self, msg_id: int, timestamp: np.ndarray, **values) -> np.ndarray:
        rec = np.zeros(len(timestamp), self.dtype)
        rec["size"], rec["kind"], rec["msg_id"] = self.dtype.itemsize - 3, ord("D"), msg_id
        rec["timestamp"] = timestamp
        for name, v in values.items():
            rec[name] = v
        return rec


TOPICS = {t.name: t for t in (
    Topic("sensor_combined", [("float", "gyro_rad", 3), ("float", "accelerometer_m_s2", 3)]),
    Topic("vehicle_attitude", [("float", "q", 4)]),
    Topic("vehicle_attitude_setpoint", [("float", "roll_body", 0), ("float", "pitch_body", 0),
                                        ("float", "yaw_body", 0), ("float", "q_d", 4)]),
    Topic("vehicle_local_position", [("float", "z", 0), ("float", "dist_bottom", 0)]),
    Topic("vehicle_local_position_setpoint", [("float", "z", 0)]),
    Topic("actuator_outputs", [("uint32_t", "noutputs", 0), ("float", "output", 4)]),
    Topic("actuator_motors", [("uint64_t", "timestamp_sample", 0), ("float", "control", 4)]),
    Topic("vehicle_angular_velocity", [("uint64_t", "timestamp_sample", 0), ("float", "xyz", 3)]),
    Topic("vehicle_rates_setpoint", [("float", "roll", 0), ("float", "pitch", 0), ("float", "yaw", 0),
                                     ("float", "thrust_body", 3)]),
    Topic("vehicle_status", [("uint8_t", "arming_state", 0), ("uint8_t", "nav_state", 0),
                             ("uint8_t", "vehicle_type", 0), ("bool", "is_vtol", 0)]),
    Topic("input_rc", [("uint64_t", "timestamp_last_signal", 0), ("int32_t", "rssi", 0),
                       ("uint8_t", "channel_count", 0), ("uint16_t", "values", 18)]),
    Topic("battery_status", [("float", "voltage_v", 0), ("float", "voltage_filtered_v", 0), ("float", "current_a", 0)]),
    Topic("distance_sensor", [("float", "min_distance", 0), ("float", "max_distance", 0),
                              ("float", "current_distance", 0), ("uint8_t", "type", 0),
                              ("uint8_t", "orientation", 0)]),
    Topic("vehicle_gps_position", [("uint64_t", "time_utc_usec", 0), ("uint8_t", "fix_type", 0)]),
    Topic("vehicle_attitude_groundtruth", [("float", "q", 4)]),
    Topic("vehicle_local_position_groundtruth", [("float", "x", 0), ("float", "y", 0), ("float", "z", 0)]),
    Topic("vehicle_magnetometer", [("uint64_t", "timestamp_sample", 0), ("float", "magnetometer_ga", 3)]),
)}


def _q(roll, pitch, yaw) -> np.ndarray:
    """Quaternions (n x 4, FRD to NED) of our Euler angle columns."""
    r, p, y = euler_ned(roll, pitch, yaw)      # works on arrays
    return np.column_stack(np.vectorize(quaternion)(r, p, y))


def flat_parameters(meta: dict[str, str], path: str) -> dict[str, float]:
    """The log's parameter file as name -> value; {} when the log carries none."""
    text = meta.get("params")
    if text is None:
        return {}
    try:
        params = from_dict(tomllib.loads(text))
    except (tomllib.TOMLDecodeError, InputError) as e:
        raise InputError(f"{path}: its '# params:' lines are not a valid parameter file ({e})") from None
    out = {}
    for prefix, obj in (("", params.airframe), ("gains.", params.gains), ("filters.", params.filters)):
        out.update({prefix + k: float(v) for k, v in vars(obj).items()})
    for k, e in enumerate(params.effects, start=1):
        out.update({f"effect{k}.{e.cause}.{name}": v for name, v in e.parameters})
    return out


def _release(version: str) -> int:
    """PX4's ver_sw_release: major, minor, patch bytes and 255 (a release)."""
    nums = [int(x) for x in version.split(".")[:3] if x.isdigit()] + [0, 0, 0]
    return (nums[0] << 24) | (nums[1] << 16) | (nums[2] << 8) | 255


def _columns(log) -> tuple[str, ...]:
    """The log's columns that the ULog carries: the contract's, the magnetometer's, the simulator's truth
    and the imported logs' extra columns (docs/log-import.md), those the CSV has; others are ignored,
    as formats.md has extra columns."""
    from flightctl.sim.logs.common import EXTRA
    return tuple(dict.fromkeys(c for c in FLIGHT_COLUMNS + MAG_COLUMNS + TRUTH + EXTRA if c in log))


def _fill(data: dict, topic: str, field: str, x: np.ndarray) -> None:
    """Put column values x into a topic's field (`name[i]`: element i of an array field, the others NaN)."""
    name, _, index = field.partition("[")
    values = data.setdefault(topic, {})
    if not index:
        values[name] = x
        return
    size = next(n for _, f, n in TOPICS[topic].fields if f == name)
    values.setdefault(name, np.full((x.size, size), np.nan))[:, int(index[:-1])] = x


def export(csv_path: str | Path, ulg_path: str | Path, px4_only: bool = False) -> dict[str, int]:
    """Write the ULog file; returns the number of samples per topic. `px4_only`: PX4's topics alone,
    without what makes the file flightctl's own (the flightctl_log topic, the flightctl_columns,
    flightctl_meta and flightctl_t0_us information messages), so that it reads as another vehicle's
    PX4 log (sim/sweeps/fleet_flown.py's simulated PX4 vehicles)."""
    from flightctl.sim.logs.common import EXTRA
    log = read_flight_log(csv_path, extra=TRUTH + EXTRA)
    meta = log.meta
    params = flat_parameters(meta, log.path)
    esc_hz = params.get("esc_pwm_hz", Airframe.esc_pwm_hz)
    try:
        t0 = float(meta.get("calibrate_s", 0.0))
    except ValueError:
        t0 = 0.0
    t0 = max(t0, -float(log["t"][0]))                  # (a log whose time starts before 0: timestamps are unsigned)
    t0_us = int(round(t0 * 1e6))
    ts = (np.round(log["t"] * 1e6).astype(np.int64) + t0_us).astype(np.uint64)     # t in whole us, as the CSV has it
    col = log.columns
    columns = _columns(log)
    n = len(ts)
    P = np.column_stack([col[f"P{i}"] for i in range(1, 5)])
    rows = {name: np.ones(n, bool) for name in TOPICS}
    for name in SPARSE:                                # a sample where one of the topic's columns has a value
        mine = [c for c in columns if c in HOMES and HOMES[c][0] == name]
        rows[name] = np.any([np.isfinite(col[c]) for c in mine], axis=0) if mine else np.zeros(n, bool)
    data: dict[str, dict] = {}
    for c in columns:                                  # each column in its home (own.py): PX4's field, or ours
        topic, field, scale = HOMES.get(c, (OWN_TOPIC, c, 1.0))
        if topic != OWN_TOPIC:
            _fill(data, topic, field, col[c][rows[topic]] / scale)
    rsp, psp, ysp = euler_ned(col["roll_sp"], col["pitch_sp"], col["yaw_sp"])
    data["vehicle_attitude"] = dict(q=_q(col["roll"], col["pitch"], col["yaw"]))
    data["vehicle_attitude_setpoint"] = dict(roll_body=rsp, pitch_body=psp, yaw_body=ysp,
                                             q_d=_q(col["roll_sp"], col["pitch_sp"], col["yaw_sp"]))
    data["vehicle_local_position"]["dist_bottom"] = col["alt"]
    data["actuator_outputs"] = dict(noutputs=4, output=pulse_us(P, esc_hz))
    data["actuator_motors"]["timestamp_sample"] = ts
    data["vehicle_angular_velocity"] = dict(timestamp_sample=ts, xyz=data["sensor_combined"]["gyro_rad"])
    data["vehicle_rates_setpoint"] = _rates_setpoint(log, params, P) | data.get("vehicle_rates_setpoint", {})
    data["battery_status"]["voltage_filtered_v"] = data["battery_status"]["voltage_v"]
    if "current" not in log:
        data["battery_status"]["current_a"] = -1.0                                   # PX4: -1 unknown
    data["distance_sensor"] |= dict(min_distance=SONAR_RANGE_M[0], max_distance=SONAR_RANGE_M[1],
                                    type=ULTRASOUND, orientation=DOWNWARD)
    if "vehicle_magnetometer" in data:
        data["vehicle_magnetometer"]["timestamp_sample"] = ts[rows["vehicle_magnetometer"]]
    if all(c in log for c in TRUTH):
        data["vehicle_attitude_groundtruth"] = dict(q=_q(col["true_roll"], col["true_pitch"], col["true_yaw"]))
    ours = own_columns(columns)
    if not px4_only:
        data[OWN_TOPIC] = {c: col[c] for c in ours}
    defined = TOPICS | {OWN_TOPIC: Topic(OWN_TOPIC, [("float", c, 0) for c in ours])}   # ours: this log's columns
    stamps = {name: ts[rows[name]] if name in rows else ts for name in data}
    second = np.unique(np.clip(np.searchsorted(log["t"], np.arange(log["t"][0], log["t"][-1], 1.0)), 0, n - 1))
    data["vehicle_status"] = dict(arming_state=ARMED, nav_state=AUTO_MISSION, vehicle_type=ROTARY_WING, is_vtol=0)
    stamps["vehicle_status"] = ts[second]
    if all(c in log for c in ("rc_roll", "rc_pitch", "rc_yaw", "rc_throttle")):
        rc = np.column_stack([1500.0 + 500.0 * col[c] for c in ("rc_roll", "rc_pitch", "rc_yaw")]
                             + [1000.0 + 1000.0 * col["rc_throttle"]])
        ok = np.isfinite(rc).all(axis=1)
        values = np.zeros((int(ok.sum()), 18))
        values[:, :4] = np.clip(rc[ok], 0, 65535)
        data["input_rc"] = dict(timestamp_last_signal=ts[ok], rssi=100, channel_count=4, values=values)
        stamps["input_rc"] = ts[ok]
    if meta.get("start_utc"):     # UTC (us) at each second of the log: PX4's vehicle_gps_position.time_utc_usec
        zero = datetime.datetime.fromisoformat(meta["start_utc"].replace("Z", "+00:00")).timestamp()
        data["vehicle_gps_position"] = dict(time_utc_usec=np.round(zero * 1e6 + ts[second].astype(float)).astype(np.uint64),
                                            fix_type=3)
        stamps["vehicle_gps_position"] = ts[second]

    head = bytearray(MAGIC + bytes([FILE_VERSION]) + struct.pack("<Q", 0))
    head += _message("B", bytes(16) + bytes(24))     # flag bits: no compatible, incompatible or appended data
    topics = [defined[name] for name in data]
    for topic in topics:
        head += topic.format()
    software = meta.get("software", f"flightctl {__version__}")
    head += _info("sys_name", NAME)
    if not px4_only:                                 # the project's own log (own.py reads it back whole)
        head += _info("flightctl_columns", ",".join(("t",) + columns[1:]))
        head += _info("flightctl_t0_us", str(t0_us))
        try:
            head += _info("flightctl_meta", json.dumps(meta))
        except ValueError:
            raise InputError(f"{log.path}: its '# key: value' lines are too long for a ULog information message "
                             f"({len(json.dumps(meta))} bytes; 65,000 at most)") from None
    head += _info("ver_sw", software)
    head += _info("ver_sw_release", _release(software.split()[-1]))
    head += _info("ver_hw", meta.get("board", "unknown"))
    head += _info("sys_toolchain", "python")
    head += _info("source_log", Path(log.path).name)
    if meta.get("vehicle_id"):                       # the vehicle and the flight's start, as PX4's logger writes them
        head += _info("sys_uuid", meta["vehicle_id"])

    short = {short_name(name): name for name in params}
    if len(short) < len(params):
        raise InputError(f"{log.path}: two parameters shorten to one PX4 name: rename one")
    head += _info("flightctl_params", ";".join(f"{k}={v}" for k, v in short.items()))
    for name, value in _vehicle_parameters(log, params).items():
        head += _parameter(name, value)
    for name, value in short.items():
        head += _parameter(name, params[value])
    for msg_id, topic in enumerate(topics):
        head += _message("A", struct.pack("<BH", 0, msg_id) + topic.name.encode())

    # data: every topic's records as raw bytes, merged into time order (stable: topics keep their order)
    chunks, times = [], []
    for msg_id, topic in enumerate(topics):
        rec = topic.records(msg_id, stamps[topic.name], **data[topic.name])
        chunks.append(rec.view(np.uint8).reshape(len(rec), rec.dtype.itemsize))
        times.append(rec["timestamp"])
    order = np.argsort(np.concatenate(times), kind="stable")
    blobs = [bytes(row) for c in chunks for row in c]
    body = b"".join([blobs[i] for i in order])
    write_atomic(ulg_path, (bytes(head), body))       # whole or not at all
    return {topic.name: len(stamps[topic.name]) for topic in topics} | {"rows": n}


def _vehicle_parameters(log, params: dict[str, float]) -> dict[str, float | int]:
    """The vehicle as PX4 describes it: a quadrotor, its rotors (the log's `# rotors:` line, else the
    paper's + layout with the arm l, eq. 25), the four main outputs as motors 1-4 with the pulse range
    of P = 0..255."""
    if "rotors" in log.meta:
        rotors = [tuple(float(v) for v in r.split()) for r in log.meta["rotors"].split(";")]
    else:
        arm = params.get("l", Airframe.l)
        rotors = [(arm, 0.0, -1.0), (0.0, arm, 1.0), (-arm, 0.0, -1.0), (0.0, -arm, 1.0)]
    esc_hz = params.get("esc_pwm_hz", Airframe.esc_pwm_hz)
    out: dict[str, float | int] = {"MAV_TYPE": 2, "CA_ROTOR_COUNT": 4}
    for i, (x, y, spin) in enumerate(rotors):
        out.update({f"CA_ROTOR{i}_PX": x, f"CA_ROTOR{i}_PY": -y, f"CA_ROTOR{i}_KM": 0.05 * spin})  # FRD; KM: spin
        out.update({f"PWM_MAIN_FUNC{i + 1}": 101 + i, f"PWM_MAIN_MIN{i + 1}": 0,
                    f"PWM_MAIN_MAX{i + 1}": int(round(pulse_us(255.0, esc_hz)))})
    return out


def _rates_setpoint(log, params: dict[str, float], P: np.ndarray) -> dict:
    """vehicle_rates_setpoint (FRD) of a log without a rate setpoint (with one, its setpoint_* columns
    are the fields: their home, own.HOMES): the rate this controller's PD commands, kp/kd times the angle
    error (eq. 24 written as an angle loop feeding a rate loop; the integral left out); the thrust, in
    every log: minus the mean command on z."""
    col = log.columns
    thrust = np.zeros((len(P), 3))
    thrust[:, 2] = -P.mean(axis=1) / 255.0
    if all(f"setpoint_{a}" in log for a in "xyz"):
        return dict(thrust_body=thrust)
    g = {k: params.get(f"gains.{k}", getattr(Gains, k)) for k in
         ("kp_phi", "kd_phi", "kp_theta", "kd_theta", "kp_psi", "kd_psi")}
    err = [col["roll_sp"] - col["roll"], col["pitch_sp"] - col["pitch"],
           (col["yaw_sp"] - col["yaw"] + np.pi) % (2 * np.pi) - np.pi]
    ours = [g[f"kp_{a}"] / g[f"kd_{a}"] * e if g[f"kd_{a}"] > 0 else np.zeros_like(e)
            for a, e in zip(("phi", "theta", "psi"), err)]
    roll, pitch, yaw = vector_ned(*ours)
    return dict(roll=roll, pitch=pitch, yaw=yaw, thrust_body=thrust)


def _import(args) -> int:
    """`flightctl log import FOREIGN OUT.csv`: another autopilot's log as this project's flight log."""
    out = output_file(args.out, suffix=".csv")
    if args.plot:
        output_file(args.plot, "--plot", ".png")
    if args.index is not None and args.index < 1:
        raise InputError(f"--index {args.index}: logs are counted from 1")
    from flightctl.sim.logs import import_text, read_figure      # after the checks: the readers and matplotlib
    from flightctl.sim.logs.common import to_table
    from flightctl.sim.plots import png
    say = (lambda *a: None) if args.quiet else (lambda m: print(f"log import: {m}", file=sys.stderr, flush=True))
    text = import_text(args.foreign, args.index, say)
    image = png(read_figure(to_table(text, str(out)))) if args.plot else None     # everything before writing
    write_atomic(out, text)
    if image is not None:
        write_atomic(args.plot, image)
    rows = text.count("\n") - sum(1 for line in text.splitlines() if line.startswith("#")) - 1
    damaged = re.search(r"^# damaged: (.*)$", text, re.M)       # a damaged log is said, not only in its header
    print(f"{args.foreign}: {rows} rows -> {out}" + (f", figure -> {args.plot}" if args.plot else "")
          + (f" (damaged: {damaged[1]})" if damaged else ""))
    return 0


def main(argv: list[str]) -> int:
    p = Parser(prog="flightctl log", description="Flight log tools.")
    sub = p.add_subparsers(dest="action", required=True)
    e = sub.add_parser("export", help="write a flight log (CSV, docs/formats.md) as PX4's ULog",
                       description=__doc__.split("\n\n")[0])
    e.add_argument("csv", metavar="FLIGHT.csv", help="a flightctl flight log")
    e.add_argument("ulg", metavar="FLIGHT.ulg", help="the ULog to write")
    i = sub.add_parser("import", help="write another autopilot's log (PX4 .ulg, ArduPilot .bin, Betaflight/INAV "
                                      ".bbl/.bfl/.txt) as a flight log (CSV, docs/formats.md); needs the logs extra",
                       description="Read a PX4 ULog, an ArduPilot DataFlash log or a Betaflight/INAV blackbox log and "
                                   "write it as this project's flight log, on the gyro's time base (the attitude's in "
                                   "a log without one), with the rotor "
                                   "layout, the command scale and the sensor filters in '# key: value' lines "
                                   "(docs/log-import.md). Of a file of many logs without --index: which hold a flight.")
    i.add_argument("foreign", metavar="FOREIGN_LOG", help="a .ulg, .bin, .bbl, .bfl, .BFL or INAV .TXT file")
    i.add_argument("out", metavar="OUT.csv", help="the flight log to write")
    i.add_argument("--index", type=int, metavar="N", help="of a file holding several logs, log N (from 1)")
    i.add_argument("--plot", metavar="OUT.png", help="also write the figure of what was read: rates, gaps, channels")
    i.add_argument("--quiet", action="store_true", help="no progress on stderr")
    args = p.parse_args(argv)
    if args.action == "import":
        return _import(args)
    out = output_file(args.ulg, suffix=".ulg")
    counts = export(args.csv, out)
    rows = counts.pop("rows")
    print(f"{args.csv}: {rows} rows -> {out} ({out.stat().st_size} bytes; "
          + ", ".join(f"{k} {v}" for k, v in counts.items()) + ")")
    return 0
