"""ArduPilot's DataFlash log (`.bin`, and its text form `.log`) through pymavlink's DFReader
(docs/log-import.md has each message, unit and frame).

ArduPilot's body frame is x forward, y right, z down (FRD), its earth frame North-East-Down: to ours
(x forward, y left, z up) y and z change sign; the accelerometer reads -g on z at rest in FRD. The
gyro's messages are the time base: `GYR` (the raw high-rate samples, where logged) else `IMU`; a log
without either (LOG_BITMASK without IMU) has ATT's as its time base and no gyro or accelerometer (`# imu:
none`), which the static tier reads (docs/diagnose.md, "Static tier").

The vehicle: the firmware (ArduCopter, ArduPlane, ...), FRAME_CLASS and FRAME_TYPE with ArduPilot's
motor positions and spins (sim/logs/frames.py: AP_MotorsMatrix's quad, hexa, octo and octo-quad matrices).
The motors: SERVOn_FUNCTION 33.. are motors 1..N of the frame's N, their pulses
in RCOU's Cn, mapped onto 0-255 over MOT_PWM_MIN..MAX (RC3_MIN..MAX when those are 0, as ArduCopter does).
ArduCopter before FRAME_CLASS (3.0-3.4: FRAME, MOT, CURR, TimeMS) is read as `arducopter3` describes.
"""
from __future__ import annotations

import contextlib
import io
import math
import os
import re
import sys
import tempfile

import numpy as np

from flightctl.sim.logs import controller
from flightctl.errors import InputError
from flightctl.files import read_bytes
from flightctl.sim.logs import arducopter3, frames, identity
from flightctl.sim.logs.dfarming import MOTOR_FUNCTION, armed as _armed
from flightctl.sim.logs.common import (CELL_FULL_V, DEG, FRD, MIN_ROWS, Imported, Stream, command_p, parser_said,
                                      rate_notes)

FRAME_CLASSES = {0: "an undefined frame", 2: "a hexacopter", 3: "an octocopter", 4: "an octo-quad (coaxial)",
                 5: "a Y6", 6: "a helicopter", 7: "a tricopter", 8: "a single-rotor vehicle", 9: "a coaxial copter",
                 10: "a tailsitter", 11: "a dual helicopter", 12: "a dodeca-hexa", 13: "a quad helicopter",
                 14: "a decacopter", 15: "a scripted frame", 16: "a scripted 6DoF frame", 17: "a scripted frame"}
QUAD = 1
MATRIX_CLASSES = sorted({c for c, _ in frames.ARDUPILOT})     # quad, hexa, octa, octa-quad (sim/logs/frames.py)
ROTORCRAFT_CLASSES = {5, 7, 12, 14}      # Y6, tricopter, dodeca-hexa, decacopter: multirotors not in the table
# (the other classes are helicopters, single and coaxial rotors, tailsitters and scripted frames)
TAKES = "diagnose knows the quad, hexa, octo and octo-quad frames (sim/logs/frames.py)"
RATE_NOTE = ("set LOG_BITMASK's IMU_FAST (and RCOUT) bits, or INS_RAW_LOG_OPT for "
             "the raw gyro (GYR)")
OLD_RATE_NOTE = ("ArduCopter before 3.3 logs IMU in its 50 Hz loop and the motor outputs in its 10 Hz loop, "
                 "whatever LOG_BITMASK says: with a newer firmware, ")
WANTED = ["PARM", "MSG", "VER", "GPS", "IMU", "GYR", "ACC", "RCOU", "RCO2", "RCO3", "BAT", "BARO", "RFND", "ATT", "RATE",
          "PIDR", "PIDP", "PIDY", "ESC", "ARM", "EV", "MOT", "CURR", "CTUN", "VIBE"]
HEADER = b"\xa3\x95"                   # every binary message starts so (then its type byte)
TAIL_BYTES = 528                      # pymavlink's allowance for garbage at a log's end (a flash page and more)
MAX_RESUMES = 100                     # readings past an unknown message type (each one a pass over the file)
PREAMBLE_LINES = 8                    # a text dump opens with a few lines (log number, firmware, board) before FMT


def preamble(head: bytes) -> list[str] | None:
    """The lines before the first FMT line of a DataFlash text log (ArduCopter's dump writes the log's
    number, the firmware, free RAM and the board there), or None when `head` is not such a log."""
    lines = head.decode("latin-1").splitlines()
    for k, line in enumerate(lines[:PREAMBLE_LINES + 1]):
        if line.startswith("FMT,"):
            return [s.strip() for s in lines[:k] if s.strip()]
    return None


def _text_reader():
    from pymavlink import DFReader

    class Text(DFReader.DFReader_text):
        """pymavlink's text reader; ArduCopter 3.0's GPS message (a time of week `Time`, no week) fails its
        clock (a TypeError in its GPS time): the boot times this reader uses are the messages' own."""
        def init_clock(self):
            try:
                super().init_clock()
            except TypeError:
                self.clock = None
                self._rewind(keep_messages=True)
    return Text


def _indexed(r) -> tuple[int, int, int]:
    """(bytes between the messages pymavlink's index found, the places they are in, the end of the last
    message found) of a binary reader `r`: its index (`offsets` per message type, each type's `len`)
    skips what does not start with a message header of a known type, byte by byte, to the next one."""
    starts, lengths = [], []
    for mtype, offsets in enumerate(r.offsets):
        if offsets and mtype in r.formats:
            starts.append(np.asarray(offsets, dtype=np.int64))
            lengths.append(np.full(len(offsets), r.formats[mtype].len, dtype=np.int64))
    if not starts:
        return 0, 0, 0
    o = np.concatenate(starts)
    order = np.argsort(o, kind="stable")
    o = o[order]
    end = np.maximum.accumulate(o + np.concatenate(lengths)[order])
    gaps = np.concatenate([[o[0]], o[1:] - end[:-1]])
    return int(gaps[gaps > 0].sum()), int((gaps > 0).sum()), int(end[-1])


def _binary(path: str):
    """pymavlink's binary reader of `path`, and a note of the damage it skipped, or None. Its index stops
    at a message header of an unknown type (a damaged type byte; TAIL_BYTES from the end it is the
    log's usual garbage): such a header is zeroed in a copy and the copy read again, so that the index
    skips it as the damaged bytes it is and reads on (at most MAX_RESUMES times; then read up to there)."""
    from pymavlink import DFReader
    with _quiet():
        r = DFReader.DFReader_binary(path, zero_time_base=False)
    skipped, places, end = _indexed(r)
    data, resumed, tmp, unknown = None, 0, None, False
    try:
        while r.data_len - end >= TAIL_BYTES and resumed < MAX_RESUMES:
            if data is None:
                data = bytearray(read_bytes(path))
            k = data.find(HEADER, end)
            while k >= 0 and k + 2 < len(data) and data[k + 2] in r.formats:
                k = data.find(HEADER, k + 1)
            unknown = 0 <= k < len(data) - 2
            if not unknown:
                break
            data[k:k + 3] = b"\0\0\0"
            resumed += 1
            if tmp is None:
                fd, tmp = tempfile.mkstemp(suffix=".bin")
                os.close(fd)
            with open(tmp, "wb") as f:
                f.write(data)
            with _quiet():
                r = DFReader.DFReader_binary(tmp, zero_time_base=False)      # (its map stays open once unlinked)
            skipped, places, end = _indexed(r)
    finally:
        if tmp is not None:
            os.unlink(tmp)
    parts = []
    if places:
        parts.append(f"damaged: {skipped} bytes in {places} places skipped (each place a message or more lost: "
                     "pymavlink reads on from the next message header)")
    if r.data_len - end >= TAIL_BYTES:
        parts.append(f"read up to byte {end} of {r.data_len}: " + (f"a message header of an unknown type there after "
                     f"{MAX_RESUMES} read past" if unknown else "no message header after it"))
    return r, "; ".join(parts) or None


@contextlib.contextmanager
def _quiet():
    """pymavlink prints a line to stderr for each damaged byte it skips (its compiled index to the process's
    own descriptor 2): the note says it once. Both are sent to /dev/null meanwhile."""
    sys.stderr.flush()
    saved = os.dup(2)
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 2)
        with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
            yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(null)


def _read(path: str, text: bool):
    """(parameters, messages by type, formats by name, texts: the preamble and MSG lines). Each message
    gets `boot_s`: its TimeUS or TimeMS in s, else (ArduCopter 3.0-3.1 write MOT, ATT, CTUN without one)
    that of the last message before it that has one."""
    try:
        from pymavlink import DFReader
    except ImportError:
        raise InputError(f"{path}: reading an ArduPilot log needs the logs extra: pip install '.[logs]' "
                         "(from the checkout)") from None
    damage = None
    try:
        if text:
            r = _text_reader()(path, zero_time_base=False)
        else:
            r, damage = _binary(path)
    except Exception as e:
        raise InputError(f"{path}: not a readable DataFlash log ({parser_said(e)})") from None
    msgs: dict[str, list] = {k: [] for k in WANTED}
    if damage:
        msgs["_skipped"] = [damage]
    boot = None
    with _quiet():
        while True:
            try:
                m = r.recv_match(type=WANTED)
            except Exception as e:          # DFReader raises what the bytes give it: read up to there
                msgs.setdefault("_damage", []).append(parser_said(e))
                break
            if m is None:
                break
            us, ms = getattr(m, "TimeUS", None), getattr(m, "TimeMS", None)
            if m.get_type() == "GPS" and us is None:   # TimeMS is the GPS week's; T (3.1-3.2) the board's ms
                ms = getattr(m, "T", None)                 # (as pymavlink's DFReaderClock_msec reads it)
            stamped = us is not None or ms is not None
            boot = us * 1e-6 if us is not None else ms * 1e-3 if ms is not None else boot
            m.boot_s, m.stamped = boot, stamped
            msgs[m.get_type()].append(m)
    _spread(msgs)
    texts = [str(getattr(m, "Message", "")) for m in msgs["MSG"]]
    if text:
        with open(path, "rb") as f:
            texts += preamble(f.read(4096)) or []
    formats = {f.name: f for f in r.formats.values()}
    return r.params, msgs, formats, texts


def _spread(msgs: dict) -> None:
    """Messages without a time stamp (ArduCopter 3.0-3.1's MOT, ATT, CTUN) spread evenly over the interval
    from the stamp before them to the next one in the log: the n of a type that share a stamp get
    stamp + j (next - stamp) / n, j = 0..n-1 (two ATT between two 5 Hz GPS fixes are 0.1 s apart; one
    MOT after each 50 Hz IMU keeps that IMU's time). After the last stamp: the type's median spacing."""
    stamps = np.unique([m.boot_s for name, ms in msgs.items() if not name.startswith("_") for m in ms
                        if m.stamped and m.boot_s is not None])
    if stamps.size == 0:
        return
    for name, ms in msgs.items():
        if name.startswith("_"):               # (the reader's own notes of damage)
            continue
        loose = [m for m in ms if not m.stamped and m.boot_s is not None]
        if not loose:
            continue
        b = np.array([m.boot_s for m in loose])
        first = np.concatenate([[True], b[1:] != b[:-1]])
        start = np.flatnonzero(first)
        count = np.diff(np.append(start, b.size))
        j = np.arange(b.size) - np.repeat(start, count)
        n = np.repeat(count, count)
        k = np.searchsorted(stamps, b, side="right")
        nxt = stamps[np.minimum(k, stamps.size - 1)]
        step = (nxt - b) / n
        inside = k < stamps.size
        if inside.any():
            step[~inside] = float(np.median(step[inside]))
        else:
            step[:] = 0.0
        for m, t in zip(loose, b + j * step):
            m.boot_s = float(t)


def _col(ms: list, name: str, instance: int | None = None, key: str = "I") -> np.ndarray:
    ms = [m for m in ms if instance is None or getattr(m, key, 0) == instance]
    return np.array([getattr(m, name) for m in ms], dtype=float)


def _t(ms: list) -> np.ndarray:
    """The messages' boot times (s)."""
    return np.array([np.nan if m.boot_s is None else m.boot_s for m in ms], dtype=float)


def _pick(ms: list, key: str) -> list:
    """The messages of instance 0 (or the lowest logged) of a multi-instance message."""
    if not ms or not hasattr(ms[0], key):
        return ms
    first = min(getattr(m, key) for m in ms)
    return [m for m in ms if getattr(m, key) == first]


def _firmware(msgs, texts: list[str]) -> str:
    for m in msgs["VER"]:
        fws = getattr(m, "FWS", "")
        if fws:
            return str(fws)
    for text in texts:
        if re.match(r"(Ardu|APM:)\w+ V\d", text) or text.startswith(("ArduCopter", "ArduPlane", "ArduRover", "ArduSub", "Rover")):
            return text                 # ("APM:Copter V3.3-dev": the name of 3.2 to 3.4)
    return ""


def _version(firmware: str) -> tuple[int, int]:
    m = re.search(r"V(\d+)\.(\d+)", firmware)
    return (int(m[1]), int(m[2])) if m else (0, 0)


def _kind(cls: int) -> str:
    return "a multirotor frame this reader does not take" if cls in ROTORCRAFT_CLASSES else frames.NOT_MULTIROTOR


def _frame(p: dict, firmware: str, formats: dict, texts: list[str], imp: Imported) -> frames.Frame:
    """The vehicle's layout (FRAME_CLASS and FRAME_TYPE, or ArduCopter 3.x's build and FRAME, through
    `frames.ardupilot`); InputError naming what the vehicle is when it is no frame of that table."""
    low = firmware.lower()
    if "plane" in low:
        imp.fail(f"{firmware}: " + ("a QuadPlane (VTOL, Q_ENABLE = 1)" if p.get("Q_ENABLE") else "a fixed wing")
                 + f", {frames.NOT_MULTIROTOR}: {TAKES}")
    if low.startswith(("rover", "ardurover", "apm:rover", "ardusub", "antennatracker", "blimp")):
        imp.fail(f"{firmware}: {frames.NOT_MULTIROTOR}: {TAKES}")
    if arducopter3.is_legacy(p):
        cls, name, why = arducopter3.frame_class(p, formats, texts)
        if cls is not None and cls not in MATRIX_CLASSES:
            imp.fail(f"{firmware or 'ArduCopter'}: {name or FRAME_CLASSES.get(cls, 'an unknown frame')} ({why}), "
                     f"{_kind(cls)}: {TAKES}")
        imp.meta["frame_class_source"] = why or ("not in the log (ArduCopter before 3.2 is built for one frame): a "
                                                 "quadrotor if no more than four outputs move")
        cls = QUAD if cls is None else cls
        ftype = arducopter3.frame_type(p, imp)
        what = f"FRAME {int(p['FRAME'])}, {why or 'a quad build'}; ArduCopter 3.x's AP_Motors{arducopter3.BUILDS[cls]}"
        return frames.ardupilot(cls, ftype, imp.fail, what)
    cls = int(p.get("FRAME_CLASS", QUAD))
    if cls not in MATRIX_CLASSES:
        imp.fail(f"FRAME_CLASS = {cls}: {FRAME_CLASSES.get(cls, 'an unknown frame')}, {_kind(cls)}: {TAKES}")
    ftype = int(p.get("FRAME_TYPE", 1))
    return frames.ardupilot(cls, ftype, lambda w: imp.fail(f"FRAME_TYPE = {ftype}: {w}"))


def _outputs(p: dict, msgs, n: int, imp: Imported) -> tuple[list[tuple[str, str]], str, str]:
    """([(message, field) of motors 1-n], which outputs in words, esc_order) from SERVOn_FUNCTION, or
    ArduCopter 3.x's fixed outputs 1-n."""
    if arducopter3.is_legacy(p):
        msg, fields = arducopter3.outputs(p, msgs, n, imp)
        if not msg:
            imp.fail("no MOT or RCOU messages: " + arducopter3.unlogged(p, True, False))
        return ([(msg, f) for f in fields], f"{msg} {', '.join(fields)} (ArduCopter 3.x: motors 1-{n} on outputs 1-{n})",
                " ".join(str(k) for k in range(n)))
    chan = {}
    for name, value in p.items():
        m = re.fullmatch(r"SERVO(\d+)_FUNCTION", name)
        if m and MOTOR_FUNCTION <= int(value) <= MOTOR_FUNCTION + 11:
            chan[int(value) - MOTOR_FUNCTION + 1] = int(m[1])
    if not chan:
        chan = {k: k for k in range(1, n + 1)}
        imp.notes.append(f"no SERVOn_FUNCTION parameters: motors 1-{n} taken on outputs 1-{n}")
    if max(chan) > n:
        imp.fail(f"motors {sorted(chan)} assigned (SERVOn_FUNCTION 33-{MOTOR_FUNCTION + max(chan) - 1}): more than "
                 f"the frame's {n} motors")
    if sorted(chan) != list(range(1, n + 1)):
        imp.fail(f"SERVOn_FUNCTION assigns motors {sorted(chan)}: the frame's motors 1-{n} are needed")
    out = []
    for m in range(1, n + 1):
        c = chan[m]
        msg = "RCOU" if c <= 14 else "RCO2" if c <= 18 else "RCO3"
        ms = msgs[msg]
        if not ms or not hasattr(ms[0], f"C{c}"):
            imp.fail(f"no {msg}.C{c} (motor {m} on SERVO{c}): the motor commands were not logged")
        out.append((msg, f"C{c}"))
    outputs = ", ".join(f"SERVO{chan[m]}" for m in range(1, n + 1))
    return (out, f"RCOU {outputs} (SERVOn_FUNCTION 33-{32 + n} = motors 1-{n})",
            " ".join(str(chan[m] - 1) for m in range(1, n + 1)))


def _motors(p: dict, msgs, n: int, imp: Imported) -> Stream:
    fields, outputs, esc_order = _outputs(p, msgs, n, imp)
    rows = [(_t(msgs[msg]), _col(msgs[msg], f)) for msg, f in fields]
    t = rows[0][0]
    raw = np.vstack([np.interp(t, tr, v) if tr.size != t.size else v for tr, v in rows])
    lo, hi = float(p.get("MOT_PWM_MIN", 0) or 0), float(p.get("MOT_PWM_MAX", 0) or 0)
    source = "MOT_PWM_MIN/MAX"
    if not 0 < lo < hi:
        lo, hi = float(p.get("RC3_MIN", 1000) or 1000), float(p.get("RC3_MAX", 2000) or 2000)
        source = ("RC3_MIN/MAX (ArduCopter 3.x drives its motors over the throttle channel's range)"
                  if arducopter3.is_legacy(p) else
                  "RC3_MIN/MAX (MOT_PWM_MIN/MAX are 0: ArduCopter then uses the throttle channel's range)")
    name = fields[0][0]
    P = command_p(imp, raw, lo, hi, f"{name} samples outside {source.split(' ')[0]} (stopped or disarmed)")
    imp.meta["motor_outputs"] = f"{outputs}; {source} {lo:g}-{hi:g} us"
    imp.meta["command_range"] = f"{lo:g} {hi:g}"
    imp.meta["command"] = f"P = 255 (pwm - {lo:g}) / ({hi:g} - {lo:g}): {outputs.split(' (')[0]} over {source.split(' ')[0]}"
    imp.meta["esc_order"] = esc_order
    return Stream(name, t, P, held=True)


def _gyro(p: dict, msgs, imp: Imported) -> tuple[bool, str, str]:
    """The gyro and accelerometer streams; (filtered by the autopilot, the gyro's source, the accelerometer's)."""
    gyr = _pick(msgs["GYR"], "I")
    imu = _pick(msgs["IMU"], "I")
    if len(gyr) >= 10 and len(_pick(msgs["ACC"], "I")) >= 10:
        acc = _pick(msgs["ACC"], "I")
        tg = _col(gyr, "SampleUS") * 1e-6
        ta = _col(acc, "SampleUS") * 1e-6
        g = np.vstack([_col(gyr, f"Gyr{a}") for a in "XYZ"])
        a = np.vstack([_col(acc, f"Acc{a}") for a in "XYZ"])
        post = int(p.get("INS_RAW_LOG_OPT", 0) or 0) & 4
        gsource = "GYR (the raw high-rate gyro samples" + (", after the filters: INS_RAW_LOG_OPT bit 2)" if post else ")")
        filtered = bool(post)
        asource = "ACC"
    elif imu:
        if not (hasattr(imu[0], "TimeUS") or hasattr(imu[0], "TimeMS")):
            imp.fail("IMU without a time stamp (ArduCopter 3.0 logs none with it): the gyro's sample times are unknown")
        tg = ta = _t(imu)
        g = np.vstack([_col(imu, f"Gyr{a}") for a in "XYZ"])
        a = np.vstack([_col(imu, f"Acc{a}") for a in "XYZ"])
        gsource, asource, filtered = "IMU (the filtered gyro the controller uses)", "IMU", True
    else:
        motors = any(msgs[k] for k in ("RCOU", "MOT"))
        why = arducopter3.unlogged(p, False, motors)
        if not motors or len(msgs["ATT"]) < MIN_ROWS:
            imp.fail("no IMU or GYR messages: " + why + ("" if len(msgs["ATT"]) >= MIN_ROWS else
                                                         "; nor ATT, the attitude a log without IMU is read on"))
        imp.meta["imu"] = f"none: {why}"       # ATT is the time base (common.time_base), gyro and acc empty
        return False, "none (no IMU or GYR messages)", "none"
    imp.streams["gyro"] = Stream(gsource.split(" ")[0], tg, g * FRD)
    imp.streams["acc"] = Stream("accelerometer", ta, a * FRD)
    return filtered, gsource, asource


def _filters(p: dict, firmware: str, texts: list[str], filtered: bool, imp: Imported) -> tuple[str, str]:
    """(gyro_filter, acc_filter): INS_GYRO_FILTER, INS_ACCEL_FILTER (biquads: the two-pole low-pass of
    every IMU sample, from ArduCopter 3.3); before them, ArduCopter 3.0-3.1 on a PX4 board:
    INS_MPU6K_FILTER, else the PX4 driver's 30 Hz two-pole low-pass at its 100 Hz IMU rate."""
    if not filtered:
        return "none", "none"
    if arducopter3.is_legacy(p) and "INS_GYRO_FILTER" not in p:
        hz = float(p.get("INS_MPU6K_FILTER", 0) or 0)
        px4 = any(t.startswith("PX4") for t in texts)
        if px4 and _version(firmware) in ((3, 0), (3, 1)):
            hz = hz or 30.0
            return f"biquad {hz:g}", f"biquad {hz:g}"
        imp.notes.append("the IMU's low-pass (INS_MPU6K_FILTER, the sensor driver's default at 0) is not declared")
        return "none", "none"
    gf, af = float(p.get("INS_GYRO_FILTER", 0) or 0), float(p.get("INS_ACCEL_FILTER", 0) or 0)
    return (f"biquad {gf:g}" if gf > 0 else "none"), (f"biquad {af:g}" if af > 0 else "none")


def read(path: str, text: bool = False) -> Imported:
    p, msgs, formats, texts = _read(path, text)
    imp = Imported(path, {}, {}, [])
    imp.notes += msgs.get("_skipped", [])
    if "_damage" in msgs:
        imp.notes.append(f"damaged: read up to where the parser stopped ({msgs['_damage'][0]})")
    armed, said, conflict = _armed(p, msgs)
    if armed is False:                 # before the vehicle: what a bench log's frame says does not matter
        imp.fail(f"never armed: the motors did not run in this log ({said})")
    if conflict:
        imp.notes.append(f"the arming's sources disagree: {conflict}")
    if armed and msgs["EV"] and not msgs["ARM"] and not any(getattr(m, "Id", -1) == 10 for m in msgs["EV"]):
        imp.notes.append(f"no EV ARMED: the log opens armed (LOG_DISARMED 0 logs from the arming only); armed by {said}")
    firmware = _firmware(msgs, texts)
    frame = _frame(p, firmware, formats, texts, imp)
    filtered, gsource, asource = _gyro(p, msgs, imp)
    imp.streams["motors"] = _motors(p, msgs, frame.count, imp)
    _measurements(p, msgs, imp)
    old = arducopter3.is_legacy(p) and _version(firmware) < (3, 3)
    rate_notes(imp, f"motor commands ({imp.streams['motors'].name})", (OLD_RATE_NOTE if old else "") + RATE_NOTE)
    gyro_filter, acc_filter = _filters(p, firmware, texts, filtered, imp)
    notches = "harmonic notch (INS_HNTCH_ENABLE)" if p.get("INS_HNTCH_ENABLE") else "none"
    imp.meta.update({
        "vehicle": "foreign", "format": "ardupilot dataflash", "source": path, "firmware": firmware,
        "craft": "", "rotors": frame.rotors(), "rotors_source": frame.source, "gyro_source": gsource, "gyro_filter": gyro_filter,
        "gyro_notches": notches, "acc_source": asource, "acc_filter": acc_filter,
    })
    imp.meta.update(identity.ardupilot(texts, p, msgs["GPS"]))
    imp.meta["controller"] = controller.encode(controller.ardupilot(p))
    return imp


def _battery(msgs, imp: Imported) -> None:
    """BAT's Volt and Curr (V, A), else ArduCopter 3.x's CURR (V x 100 and A x 100 in its integer fields)."""
    bat = _pick(msgs["BAT"], "Inst")
    name = "BAT"
    if not bat and msgs["CURR"] and hasattr(msgs["CURR"][0], "Volt"):
        bat, name = msgs["CURR"], "CURR"
    if not bat:
        return
    fmt = dict(zip(bat[0].fmt.columns, bat[0].fmt.format))
    scale = {k: 0.01 if fmt.get(k, "f") in "hHiI" else 1.0 for k in ("Volt", "Curr")}
    tb = _t(bat)
    v = _col(bat, "Volt") * scale["Volt"]
    ok = v > 0.5
    imp.streams["battery_v"] = Stream(f"{name} Volt", tb[ok], v[None, ok])
    if hasattr(bat[0], "Curr"):
        cur = _col(bat, "Curr") * scale["Curr"]
        if np.any(cur > 0):
            imp.streams["current"] = Stream(f"{name} Curr", tb, cur[None])


def _measurements(p: dict, msgs, imp: Imported) -> None:
    _battery(msgs, imp)
    vmax = float(p.get("MOT_BAT_VOLT_MAX", 0) or 0)
    if vmax > 0:
        imp.meta["battery_cells"] = str(max(1, round(vmax / CELL_FULL_V)))
        imp.meta["battery_cells_source"] = f"MOT_BAT_VOLT_MAX {vmax:g} V over {CELL_FULL_V:g} V a cell"
    baro = _pick(msgs["BARO"], "I")
    imp.meta["height_source"] = "none"
    if baro:
        imp.streams["height"] = Stream("BARO Alt (above the ground at boot)", _t(baro), _col(baro, "Alt")[None])
        imp.meta["height_source"] = "baro"
    elif msgs["CTUN"] and hasattr(msgs["CTUN"][0], "BarAlt"):
        ctun = msgs["CTUN"]
        imp.streams["height"] = Stream("CTUN BarAlt (the barometer above the ground at boot)", _t(ctun),
                                       _col(ctun, "BarAlt")[None])
        imp.meta["height_source"] = "baro"
    rf = [m for m in msgs["RFND"] if getattr(m, "Orient", 25) == 25 and getattr(m, "Stat", 4) == 4]
    if rf:
        dist = _col(rf, "Dist")
        imp.streams["range"] = Stream("RFND Dist (downward)", _t(rf), dist[None])
    att = msgs["ATT"]
    if att:
        e = np.vstack([_col(att, k) for k in ("Roll", "Pitch", "Yaw")]) * DEG
        e[2] = np.unwrap(e[2])
        imp.streams["attitude"] = Stream("ATT", _t(att), e * FRD)
        if hasattr(att[0], "DesRoll"):
            d = np.vstack([_col(att, k) for k in ("DesRoll", "DesPitch", "DesYaw")]) * DEG
            d[2] = np.unwrap(d[2])
            imp.streams["attitude_sp"] = Stream("ATT DesRoll/DesPitch/DesYaw", _t(att), d * FRD)
    rate = msgs["RATE"]
    if rate:
        sp = np.vstack([_col(rate, k) for k in ("RDes", "PDes", "YDes")]) * DEG
        imp.streams["setpoint"] = Stream("RATE RDes/PDes/YDes", _t(rate), sp * FRD)
    _pid_targets(msgs, imp)
    _vibe(msgs, imp)
    _thrust_curve(p, imp)
    _landed(msgs, imp)
    order = [int(k) for k in imp.meta.pop("esc_order").split()]
    esc = msgs["ESC"]
    if esc and hasattr(esc[0], "RPM"):             # one ESC instance per motor output, any motor count
        inst = {i: [m for m in esc if getattr(m, "Instance", -1) == i] for i in order}
        if all(inst[i] for i in order):
            t = _t(inst[order[0]])
            w = np.vstack([np.interp(t, _t(inst[i]), _col(inst[i], "RPM")) for i in order])
            if np.any(w != 0):
                imp.streams["omega"] = Stream("ESC RPM", t, np.abs(w) * 2.0 * math.pi / 60.0)
                imp.meta["omega_source"] = (f"ESC telemetry RPM of instances {', '.join(map(str, order))} (the motors' "
                                            f"output channels) for motors 1-{len(order)}")


def _landed(msgs, imp: Imported) -> None:
    """The landing detector's state from EV (dfarming.ARMED_EVENTS): NOT_LANDED 28 the take-off, LAND_COMPLETE 18
    the landing; landed before the first NOT_LANDED (not landed from the log's start when LAND_COMPLETE comes
    first: a log that opens in the air), held between them."""
    ev = [m for m in msgs["EV"] if int(getattr(m, "Id", -1)) in (18, 28)]
    if not ev or "gyro" not in imp.streams:
        return
    t = np.concatenate([[imp.streams["gyro"].t[0]], _t(ev)])
    v = np.array([1.0 if int(ev[0].Id) == 28 else 0.0] + [1.0 if int(m.Id) == 18 else 0.0 for m in ev])
    order = np.argsort(t, kind="stable")
    imp.streams["landed"] = Stream("EV NOT_LANDED / LAND_COMPLETE", t[order], v[order][None], held=True)
    imp.meta["landed_source"] = "ArduCopter's EV 28 NOT_LANDED and 18 LAND_COMPLETE"


def _pid_targets(msgs, imp: Imported) -> None:
    """The rate setpoint from PIDR/PIDP/PIDY's Tar (rad/s, FRD: ArduCopter 4.x's rate PIDs' target, logged at the
    loop's rate with LOG_BITMASK's PID bit; backend_log_80k.bin's PIDR Tar 0.306 beside RATE RDes 17.3 deg/s)
    where it is logged faster than RATE (10 Hz by default)."""
    pid = [msgs[k] for k in ("PIDR", "PIDP", "PIDY")]
    if not all(len(m) >= 2 and hasattr(m[0], "Tar") for m in pid):
        return
    t = _t(pid[0])
    sp = np.vstack([np.interp(t, _t(m), _col(m, "Tar")) for m in pid])
    s = Stream("PIDR/PIDP/PIDY Tar", t, sp * FRD)
    if "setpoint" not in imp.streams or s.rate_hz() > imp.streams["setpoint"].rate_hz():
        imp.streams["setpoint"] = s


def _vibe(msgs, imp: Imported) -> None:
    """VIBE's VibeX/Y/Z (m/s^2, the accelerometer's standard deviation; of the first IMU where 4.x logs one
    per IMU) and its clip count (Clip0 + Clip1 + Clip2 before 4.x, Clip after), cumulative."""
    vibe = _pick(msgs["VIBE"], "IMU")
    if not vibe:
        return
    t = _t(vibe)
    imp.streams["vibe"] = Stream("VIBE", t, np.vstack([_col(vibe, f"Vibe{a}") for a in "XYZ"]))
    names = [c for c in ("Clip", "Clip0", "Clip1", "Clip2") if hasattr(vibe[0], c)]
    if names:
        imp.streams["clip"] = Stream("VIBE " + "+".join(names), t, sum(_col(vibe, c) for c in names)[None], held=True)


def _thrust_curve(p: dict, imp: Imported) -> None:
    """`thrust_curve` from MOT_THST_EXPO and the spin range (MOT_SPIN_MIN/MAX; MOT_THST_MAX before 3.5,
    which had no MOT_SPIN_MIN: 0 there), AP_MotorsMulticopter's thrust linearisation."""
    if "MOT_THST_EXPO" not in p:
        return
    e = float(p["MOT_THST_EXPO"])
    lo = float(p.get("MOT_SPIN_MIN", 0.0))
    hi = float(p.get("MOT_SPIN_MAX", p.get("MOT_THST_MAX", 0.95)))
    if 0.0 <= e <= 1.0 and 0.0 <= lo < hi <= 1.0:
        imp.meta["thrust_curve"] = f"expo {e:.4g} spin {lo:.4g} {hi:.4g}"
        imp.meta["thrust_curve_source"] = ("ArduPilot's MOT_THST_EXPO " + f"{e:.4g}, spin range {lo:.4g}-{hi:.4g} of "
                                           "the output (MOT_SPIN_MIN/MAX" + ("" if "MOT_SPIN_MIN" in p else
                                                                           "; MOT_THST_MAX, no MOT_SPIN_MIN: 0") + ")")
