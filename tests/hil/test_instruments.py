"""The bench's instruments: the line protocol, the RCbenchmark stream (real files from ../shared/data/real,
never copied here) through a pty and pyserial, the Pi bench with a microcontroller on a pty, and the
clamped confirmation."""
from __future__ import annotations

import csv
import math
import os
import threading
import time
import tty
from functools import reduce

import pytest

from helpers.fakes.pigpiod import running
from helpers.real import need
from flightctl.boards import Board
from flightctl.errors import InputError
from flightctl.hil import bench
from flightctl.hil import instruments as ins
from flightctl.params import load
from flightctl.boards.pi import open_pi_board
from flightctl.sim.world.devices import SensorNoise, World
from flightctl.sim.world.imu import SimMpu9250
from flightctl.sim.world.power import SimIna219, SimSMBus
from helpers.paths import ROOT

RCB_DIR = ROOT / ".." / "shared" / "data" / "real" / "rcbenchmark"


def nmea(body: str) -> str:
    return f"${body}*{reduce(lambda a, c: a ^ ord(c), body, 0):02X}"


def test_protocol_lines_parse_to_si_and_bad_lines_are_refused():
    s = ins.parse_fcb(nmea("FCB,1500.0,510.0,6000,16.020,3.200"))
    assert s.t == pytest.approx(1.5) and s.thrust == pytest.approx(0.510 * 9.80665)
    assert s.omega == pytest.approx(6000 * 2 * math.pi / 60)
    assert (s.voltage, s.current) == (pytest.approx(16.02), pytest.approx(3.2))
    s = ins.parse_fcb(nmea("FCB,20,-3.5,0"))                 # no supply fields: the INA219 gives them
    assert math.isnan(s.voltage) and s.thrust < 0
    assert ins.parse_fcb("# fcbench 1.0, HX711 at 80 SPS") is None
    assert ins.parse_fcb(ins.encode(12.0, 100.0, 3000.0)).omega == pytest.approx(3000 * 2 * math.pi / 60)
    good = nmea("FCB,20,10.0,900")
    for bad in (good.replace("900", "901"), good[:-1], good.replace("$", ""), nmea("FCB,20,10.0"),
                nmea("FCB,20,ten,900"), nmea("XYZ,20,10.0,900"), nmea("FCB,20,10.0,-5")):
        with pytest.raises(ValueError):
            ins.parse_fcb(bad)


def _pty_port(parse, commands=False):
    master, slave = os.openpty()
    tty.setraw(slave)
    ser = ins.open_serial(os.ttyname(slave), 115200)
    os.close(slave)
    return master, ins.Instruments(ser, parse, "test", commands)


def test_the_rcbenchmark_stream_through_a_pty_gives_its_rows_in_si():
    path = sorted(need(RCB_DIR).glob("StepsTest_2020*.csv"))[0]
    text = path.read_text(encoding="utf-8")
    rows = list(csv.DictReader(text.lstrip("\ufeff").splitlines()))
    master, port = _pty_port(ins.RcbenchmarkParser())
    writer = threading.Thread(target=lambda: os.write(master, text.encode("utf-8")) and None)
    writer.start()
    got, deadline = [], time.monotonic() + 5
    while len(got) < len(rows) and time.monotonic() < deadline:
        got += port.poll(now=time.monotonic())
        time.sleep(0.005)
    writer.join()
    port.close()
    os.close(master)
    assert len(got) == len(rows) and port.bad == 0
    for (t, s), row in zip(got, rows):
        rpm = float(row["Motor Optical Speed (RPM)"] or 0) or float(row["Motor Electrical Speed (RPM)"])
        assert s.thrust == pytest.approx(float(row["Thrust (gf)"]) * 9.80665e-3)
        assert s.omega == pytest.approx(rpm * math.pi / 30)
        assert s.voltage == pytest.approx(float(row["Voltage (V)"]))
        assert s.current == pytest.approx(float(row["Current (A)"]))


def test_the_pi_bench_reads_the_microcontroller_while_the_motor_spins(tmp_path):
    """The Pi board (fake pigpiod, simulated INA219 registers) and a microcontroller played on a pty: it
    acknowledges M2 and Z and streams samples; a corrupted line is dropped and counted."""
    params = load(None)
    world = World(params.airframe, noise=SensorNoise.off())
    world.battery.voltage, world.battery.current = 16.0, 3.2
    master, port = _pty_port(ins.parse_fcb, commands=True)
    os.set_blocking(master, False)
    heard, stop = [], threading.Event()

    def firmware():
        inbox, t0, k = b"", time.monotonic(), 0
        while not stop.wait(0.01):
            try:
                inbox += os.read(master, 64)
            except BlockingIOError:
                pass
            *cmds, inbox = inbox.split(b"\n")
            for c in cmds:
                heard.append(c.decode())
                os.write(master, b"#ok " + c + b"\n")
            k += 1
            line = ins.encode((time.monotonic() - t0) * 1e3, 510.0, 6000.0)
            os.write(master, (line.replace("*", "0*") if k == 5 else line).encode())   # one corrupted line

    fw = threading.Thread(target=firmware, daemon=True)
    fw.start()
    with running() as (fake, pi):
        board = open_pi_board(params, None, pi=pi, spi=SimMpu9250(world), smbus=SimSMBus(SimIna219(world)))
        hal = board.hal
        b = bench.Bench(hal, port, bench.Limits(max_omega=700.0), ramp=500)
        hal.motors.stop()
        hal.motors.arm()
        b.start_motor(2)
        row = b.steady(150, 0.05, 0.2)
        on_times = fake.live_wave().on_times()
        b.finish()
        board.close()
    stop.set()
    fw.join()
    port.close()
    os.close(master)
    assert heard == ["M2", "Z"]
    assert on_times[27] == round(150 / 255 * 2227)                           # motor 2 at P = 150 (GPIO 27)
    assert on_times[17] == on_times[22] == on_times[25] == 1000               # the others at the stop pulse
    motor, P, thrust, omega, volts, amps = row
    assert (motor, P) == (2, 150) and thrust == pytest.approx(0.510 * 9.80665)
    assert omega == pytest.approx(6000 * math.pi / 30)
    assert volts == pytest.approx(16.0, abs=0.01) and amps == pytest.approx(3.2, abs=0.01)   # from the INA219
    assert port.bad == 1
    assert fake.live_wave().on_times()[27] == 1000 and fake.errors == []


def test_hardware_needs_the_clamped_confirmation(monkeypatch):
    args = bench.parse_args(["--board", "pi"])
    pi_board = Board(hal=None, name="pi", min_battery_v=0.0, calibrate_s=0.0)
    monkeypatch.setattr("sys.stdin.isatty", lambda: False)
    with pytest.raises(InputError, match="--clamped"):
        bench.confirm_clamped(args, pi_board)
    monkeypatch.setattr("sys.stdin.isatty", lambda: True)
    with pytest.raises(InputError, match="not confirmed"):
        bench.confirm_clamped(args, pi_board, read=lambda prompt: "yes")
    bench.confirm_clamped(args, pi_board, read=lambda prompt: "clamped")
    bench.confirm_clamped(bench.parse_args(["--board", "pi", "--clamped"]), pi_board, read=lambda p: pytest.fail())
    assert bench.parse_args(["--board", "pi"]).instruments == "serial:/dev/ttyACM0,115200"
    with pytest.raises(InputError, match="one motor"):
        bench.main(["--board", "sim", "--instruments", "rcbenchmark:/dev/ttyUSB0"])
