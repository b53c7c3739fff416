"""`flightctl bench`: one motor at a time, the others at the stop pulse, a ramp, a maximum, a stop on
Ctrl-C, and bench.csv rows: the simulator's truth on --board sim, the operator's entries on the Pi."""
from __future__ import annotations

import math
import time

import pytest

from fakes.pigpiod import running
from flightctl.cli import main as cli
from flightctl.errors import InputError
from flightctl.logfile import BENCH_COLUMNS, read_table
from flightctl.params import load
from flightctl.pi import open_pi_board
from flightctl.hil import bench
from flightctl.sim.devices import SensorNoise, SimMpu9250, World
from without import PI_LIBRARIES, run_without
from flightctl.sim.power import SimIna219, SimSMBus


def test_sim_bench_writes_the_models_truth(tmp_path):
    out = tmp_path / "bench.csv"
    assert bench.main(["--board", "sim", "--motor", "3", "--steps", "130,160,190", "--settle", "0.3",
                       "--hold", "0.3", "--out", str(out)]) == 0
    table = read_table(out, BENCH_COLUMNS)
    a = load(None).airframe
    assert list(table["motor"]) == [3, 3, 3] and list(table["P"]) == [130, 160, 190]
    for P, f, w in zip(table["P"], table["thrust"], table["omega"]):
        assert f == pytest.approx(a.h1 * (P - a.h2) ** 2, rel=1e-3)          # eq. 26 (P quantised to counts)
        assert w == pytest.approx(math.sqrt(f / a.c1), rel=1e-5)             # eq. 27 (6 digits in the file)
    assert all(15.0 < v < 16.8 for v in table["voltage"])
    assert table["current"][2] > table["current"][0] > 0
    assert table.meta["board"].startswith("sim")


def test_bench_keeps_the_other_motors_stopped_and_ramps(monkeypatch, tmp_path):
    writes = []
    real_open = bench.open_bench

    def recording_open(args, params):
        board, truth = real_open(args, params)
        real_write = board.hal.motors.write
        board.hal.motors.write = lambda c: (writes.append(list(c)), real_write(c))
        return board, truth

    monkeypatch.setattr(bench, "open_bench", recording_open)
    assert bench.main(["--board", "sim", "--motor", "2", "--steps", "180", "--ramp", "100", "--settle", "0.1",
                       "--hold", "0.1", "--out", str(tmp_path / "b.csv")]) == 0
    assert all(c[0] == c[2] == c[3] == 0 for c in writes)
    motor2 = [c[1] for c in writes]
    steps = [b - a for a, b in zip(motor2, motor2[1:])]
    max_step = 100 / 450 / 255 * 40000 + 1                                   # 100 P/s at 450 Hz, in counts
    assert max(abs(s) for s in steps) <= max_step
    assert max(motor2) == round(180 / 255 * 40000) and motor2[-1] == 0        # ramped down at the end


def test_steps_above_the_maximum_or_a_bad_motor_are_refused(tmp_path, capsys):
    assert cli(["bench", "--board", "sim", "--motor", "1", "--steps", "150,230", "--out", str(tmp_path / "b.csv")]) == 2
    assert "exceeds --max 200" in capsys.readouterr().err
    assert cli(["bench", "--board", "sim", "--motor", "5", "--steps", "150"]) == 2
    assert not (tmp_path / "b.csv").exists()
    with pytest.raises(InputError):
        bench.parse_steps("150,abc", 200)


def test_ctrl_c_stops_the_motor_and_keeps_the_rows_so_far(monkeypatch, tmp_path):
    state = {}
    real_open = bench.open_bench

    def interrupting_open(args, params):
        board, truth = real_open(args, params)
        hal = board.hal
        state["motors"] = hal.motors
        reads = [0]
        real_read = hal.power.read

        def read():
            reads[0] += 1
            if reads[0] > 6:                    # during the second step's measurement
                raise KeyboardInterrupt
            return real_read()

        hal.power.read = read
        return board, truth

    monkeypatch.setattr(bench, "open_bench", interrupting_open)
    out = tmp_path / "b.csv"
    assert bench.main(["--board", "sim", "--motor", "1", "--steps", "150,170", "--settle", "0.1", "--hold", "0.5",
                       "--out", str(out)]) == 130
    assert state["motors"].counts == [0, 0, 0, 0] and not state["motors"].armed
    assert len(read_table(out, BENCH_COLUMNS)) == 1


def test_pi_bench_takes_the_operators_readings_while_the_motor_keeps_spinning(tmp_path):
    params = load(None)
    world = World(params.airframe, noise=SensorNoise.off())
    world.battery.voltage, world.battery.current = 16.0, 3.2
    bus = SimSMBus(SimIna219(world))
    with running() as (fake, pi):
        board = open_pi_board(params, None, pi=pi, spi=SimMpu9250(world), smbus=bus)
        hal = board.hal
        seen = {}

        def operator(motor, P):
            time.sleep(0.3)                     # three dead-man periods: the holder keeps writing
            seen["on_times"] = fake.live_wave().on_times()
            seen["script"] = fake.script_running()
            answers = iter(["510", ""])         # scale 510 g; tachometer skipped with Enter
            return bench.ask_operator(motor, P, read=lambda prompt: next(answers))

        b = bench.Bench(hal, 2, truth=None, ask=operator, ramp=500, settle_s=0.05, hold_s=0.1)
        hal.motors.stop()
        hal.motors.arm()
        row = b.step(150)
        b.finish()
        board.close()
    assert seen["script"]                                                 # armed throughout
    assert seen["on_times"][27] == round(150 / 255 * 40000 / 40000 * 2227)  # motor 2 still at P = 150
    assert seen["on_times"][17] == seen["on_times"][22] == seen["on_times"][25] == 1000
    motor, P, thrust, omega, volts, amps = row
    assert (motor, P) == (2, 150)
    assert thrust == pytest.approx(0.510 * 9.80665)
    assert math.isnan(omega)                                              # skipped with Enter
    assert volts == pytest.approx(16.0, abs=0.01) and amps == pytest.approx(3.2, abs=0.01)
    assert fake.live_wave().on_times()[27] == 1000 and fake.errors == []


def test_an_unknown_board_or_a_pi_board_that_is_not_there_is_one_line(tmp_path, capsys):
    assert cli(["bench", "--board", "bench9", "--motor", "1", "--steps", "150"]) == 2
    assert capsys.readouterr().err.strip() == "flightctl bench: error: unknown board 'bench9' (known: pi, sim)"
    board = tmp_path / "board.toml"
    board.write_text("[pigpio]\nport = 1\n")              # nothing listens on port 1
    out = tmp_path / "b.csv"
    assert cli(["bench", "--board", "pi", "--board-file", str(board), "--motor", "1", "--steps", "150",
                "--out", str(out)]) == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("flightctl bench: cannot open the pi board: cannot reach pigpiod")
    assert not out.exists()


def test_the_pi_bench_on_a_machine_without_the_pi_libraries_is_one_line(tmp_path):
    r = run_without(PI_LIBRARIES, ["bench", "--board", "pi", "--motor", "1", "--steps", "150"], tmp_path)
    assert r.returncode == 3
    assert r.stderr.strip().splitlines() == [
        "flightctl bench: cannot open the pi board: the pi board needs the Python module 'pigpio', which is not "
        "installed (install the Pi libraries with pip install 'flightctl[pi]')"]
    assert not (tmp_path / "bench.csv").exists()
