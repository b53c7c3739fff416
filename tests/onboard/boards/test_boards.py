"""The board registry (flightctl/boards/__init__.py): boards opened by name, one `Board` for every command,
the simulated board lock-step or paced by the wall clock, and a new board added with one line."""
from __future__ import annotations

import math

import pytest

from flightctl.boards import BOARDS, MIN_BATTERY_V, Board, BoardOptions, BoardUnavailable, Entry, open_board, \
    stop_motors
from flightctl.clock import PacedClock
from flightctl.errors import InputError
from flightctl.hal import Hal
from flightctl.params import load
from flightctl.sim.world.board import SIM_CALIBRATE_S, TRUTH_COLUMNS
from flightctl.sim.world.devices import SensorNoise, SimClock

opened = []


def open_toy(params, options):
    """A board for this test: what a new module's opener looks like."""
    opened.append(options)
    return Board(Hal(None, None, None, None, None), "toy", 10.0, 0.5)


def test_the_sim_board_by_name_is_lock_step_unless_asked_for_real_time():
    params = load(None)
    board = open_board("sim", params, BoardOptions(seed=4, noise=SensorNoise.off()))
    assert board.name == "sim" and isinstance(board.hal.clock, SimClock)
    assert (board.min_battery_v, board.calibrate_s) == (MIN_BATTERY_V, SIM_CALIBRATE_S)
    assert board.extra_columns == TRUTH_COLUMNS and board.meta["seed"] == "4"
    plant = board.world.plant
    plant.x[2], plant.x[8] = 0.7, 3 * math.pi / 2                 # up 0.7 m, heading 270 deg
    row = board.extra_row()
    assert len(row) == len(TRUTH_COLUMNS)
    assert row[2] == 0.7 and row[5] == pytest.approx(-math.pi / 2)  # yaw wrapped to (-pi, pi]
    paced = open_board("sim", params, BoardOptions(realtime=True))
    assert isinstance(paced.hal.clock, PacedClock) and "wall clock" in paced.meta["clock"]


def test_a_board_is_one_module_and_one_registry_line(monkeypatch):
    monkeypatch.setitem(BOARDS, "toy", Entry("test_boards:open_toy", "a test board"))
    options = BoardOptions(board_file="wiring.toml")
    board = open_board("toy", load(None), options)
    assert board.name == "toy" and opened[-1] is options
    assert stop_motors("toy", load(None)) == "nothing to do on the toy board"


def test_unknown_boards_and_missing_libraries_are_one_line(monkeypatch):
    with pytest.raises(InputError, match=r"^unknown board 'toy2' \(known: pi, pi5, auto, sim, hil\)$"):
        open_board("toy2", load(None))
    monkeypatch.setitem(BOARDS, "toy3", Entry("toy3_driver_library:open", "needs a library", None, "pip install toy3"))
    with pytest.raises(BoardUnavailable, match=r"needs the Python module 'toy3_driver_library', which is not "
                                               r"installed \(pip install toy3\)"):
        open_board("toy3", load(None))
    # one of our own modules missing is a bug, not a missing library: it is not hidden
    monkeypatch.setitem(BOARDS, "toy4", Entry("flightctl.no_such_board:open", "a typo in the registry"))
    with pytest.raises(ModuleNotFoundError):
        open_board("toy4", load(None))
