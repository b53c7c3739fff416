"""Which vehicle a log is of, and when its flight started, as each autopilot writes them: the readers
put them in the log's header (`vehicle_id`, `start_utc`, each with its `_source`), and the fleet
report (sim/diagnose/fleet/) groups and orders the logs by them.

- ArduPilot (DataFlash): the board's name and its three 32-bit unique-ID words in a MSG line at boot
  (`Pixhawk4 0047002B 34385105 36363539` in tests/data/ardupilot/backend_log_80k.bin; AP_BoardConfig
  writes `hal.util->get_system_id`), else BRD_SERIAL_NUM when it is set (not 0); the start from the
  first GPS message with a fix (GWk, GMS: the GPS week and its ms, GPS time, ahead of UTC by the leap
  seconds since 1980: 18 s since 2017-01-01).
- PX4 (ULog): the `sys_uuid` information message (the logger's: the board's UUID); the start from the GPS
  topic's `time_utc_usec` (vehicle_gps_position, or sensor_gps: UTC in microseconds) of its first fix,
  less its timestamp (PX4's `time_ref_utc` information message is the UTC offset of the local time, not
  a time: 0 in ../shared/data/real/flights/px4's logs).
- Betaflight and INAV (blackbox): `Craft name` with `Board information` from the header (which craft the
  pilot named, on which board); a board's name alone is its model (`MTKS MATEKH743`: every Matek H743 says
  so), not a vehicle: it is kept as `board` and the log is grouped by its folder (issue 45: three
  INDIflight logs of different vehicles, one board model, no craft name); the start from `Log start
  datetime` (its RTC's: 0000-01-01 when unset).
"""
from __future__ import annotations

import datetime as dt
import re

GPS_EPOCH = dt.datetime(1980, 1, 6, tzinfo=dt.timezone.utc)
GPS_LEAP_S = 18
UID_LINE = re.compile(r"^(\S+) ([0-9A-Fa-f]{8}) ([0-9A-Fa-f]{8}) ([0-9A-Fa-f]{8})$")


def _iso(when: dt.datetime) -> str:
    return when.astimezone(dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%S.%fZ")


def gps_utc(week: float, ms: float) -> str:
    """A GPS week and ms of the week as UTC (ISO 8601)."""
    return _iso(GPS_EPOCH + dt.timedelta(weeks=float(week), milliseconds=float(ms), seconds=-GPS_LEAP_S))


def ardupilot(texts: list[str], params: dict, gps: list) -> dict[str, str]:
    """The header lines of an ArduPilot log (the module's docstring)."""
    out = {}
    for text in texts:
        if m := UID_LINE.match(text.strip()):
            out["vehicle_id"] = f"{m[1]} {m[2].upper()} {m[3].upper()} {m[4].upper()}"
            out["vehicle_id_source"] = "ArduPilot's board UID (MSG at boot)"
            break
    else:
        serial = params.get("BRD_SERIAL_NUM")
        if serial:
            out["vehicle_id"] = f"BRD_SERIAL_NUM {int(serial)}"
            out["vehicle_id_source"] = "ArduPilot's BRD_SERIAL_NUM"
    for m in gps:
        week, ms = getattr(m, "GWk", None), getattr(m, "GMS", None)
        if week and ms is not None and getattr(m, "Status", 0) >= 3:
            boot = getattr(m, "boot_s", None) or 0.0
            out["start_utc"] = gps_utc(week, ms - 1000.0 * boot)     # back to the log's time zero
            out["start_source"] = "GPS time (GWk, GMS) of the first 3D fix, less its time since boot"
            break
    return out


def px4(info: dict, gps: dict | None) -> dict[str, str]:
    """The information messages and the GPS topic's data (vehicle_gps_position or sensor_gps) of a ULog."""
    out = {}
    uuid = str(info.get("sys_uuid", "")).strip()
    if uuid:
        out["vehicle_id"], out["vehicle_id_source"] = uuid, "PX4's sys_uuid"
    if gps is not None and "time_utc_usec" in gps:
        fix = [k for k, v in enumerate(gps["time_utc_usec"]) if v > 0]
        if fix:
            k = fix[0]
            zero = (int(gps["time_utc_usec"][k]) - int(gps["timestamp"][k])) * 1e-6
            out["start_utc"] = _iso(dt.datetime.fromtimestamp(zero, dt.timezone.utc))
            out["start_source"] = "PX4's GPS time (time_utc_usec of the first fix, less its timestamp)"
    return out


def blackbox(header: dict) -> dict[str, str]:
    out = {}
    board, craft = str(header.get("Board information", "")).strip(), str(header.get("Craft name", "")).strip()
    if board:
        out["board"] = board
    if craft:
        out["vehicle_id"] = " / ".join(x for x in (board, craft) if x)
        out["vehicle_id_source"] = "the blackbox header's Craft name" + (" and Board information" if board else "")
    when = str(header.get("Log start datetime", "")).strip()
    if when and not when.startswith("0000"):
        try:
            out["start_utc"] = _iso(dt.datetime.fromisoformat(when.replace("Z", "+00:00")))
            out["start_source"] = "the blackbox header's Log start datetime"
        except ValueError:
            pass
    return out
