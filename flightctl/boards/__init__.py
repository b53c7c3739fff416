"""The board registry: every board by name, resolved like the CLI's command table, so that the
onboard package names the simulator without importing it (layers import one way, docs/architecture.md).

    board = open_board("sim", params, BoardOptions(seed=3))     # or "pi"
    ... board.hal ...; board.close()

An opener `open_board(params, options) -> Board` wires the drivers (or the simulated devices) into a
`Hal` and says what the commands need to know about the board: its name, the battery voltage below
which it refuses to arm, how long it sits still calibrating, extra log columns (the simulator's
truth) and metadata. `flightctl run`, `flightctl sim` and `flightctl bench` open boards only through
this; no other module asks which board it runs on. Adding a board: one module with an opener (and,
if it drives real ESCs, a `stop_motors`), and one line in BOARDS.
"""
from __future__ import annotations

import importlib
import os
from dataclasses import dataclass, field
from typing import Callable, NamedTuple

from flightctl.errors import InputError
from flightctl.hal import Hal
from flightctl.battery import CELLS, FULL_CELL_V, LOW_CELL_V, MIN_CELL_V
from flightctl.params import Params

MIN_BATTERY_V = MIN_CELL_V * CELLS      # the default pre-arm threshold of every board
# The pre-arm threshold a board file or `run --min-battery-v` may set: from the voltage the loop lands at
# (below it, a vehicle would arm into a landing: a lower threshold turns the check off) to a full pack's
# (above it, nothing could ever arm).
MIN_BATTERY_V_RANGE = (LOW_CELL_V * CELLS, FULL_CELL_V * CELLS)


class Entry(NamedTuple):
    opener: str                     # "module:function" -> Board
    doc: str
    stop_motors: str | None = None  # "module:function" -> what was done; the unit's ExecStopPost
    install: str = ""               # how to get what the board's module imports


BOARDS = {
    "pi": Entry("flightctl.boards.detect:open_pi", "the quadcopter on a Raspberry Pi 3/4 (pigpio): the drivers wired from the board file",
                "flightctl.boards.detect:stop_pi", "install the Pi libraries with pip install '.[pi]' in the flightctl checkout"),
    "pi5": Entry("flightctl.boards.pi5:open_board", "the quadcopter on a Raspberry Pi 5 (the kernel's PWM and GPIO)",
                 "flightctl.boards.pi5:stop_motors", "install the Pi 5 libraries with pip install '.[pi5]' in the flightctl checkout"),
    "auto": Entry("flightctl.boards.detect:open_auto", "pi5 on a Raspberry Pi 5, pi on any other (the device tree's model)",
                  "flightctl.boards.detect:stop_auto"),
    "sim": Entry("flightctl.sim.world.board:open_board",
                 "the simulated quadcopter behind the real IMU and sonar drivers"),
    "hil": Entry("flightctl.boards.hil:open_board", "the flight code flying a plant on a PC over --link (flightctl hil serve)"),
}


class BoardUnavailable(Exception):
    """The board cannot be brought up: a library missing, a device not reachable (pigpiod not
    running, no SPI or I2C device node), or the wrong device answering."""


@dataclass(frozen=True)
class BoardOptions:
    """What a command may ask of a board; each board uses the fields that concern it."""
    board_file: str | None = None   # pi, pi5: the wiring file (default: the shipped flightctl/boards/pi.toml, pi5.toml)
    seed: int = 0                   # sim: the sensor-noise seed
    realtime: bool = False          # sim: pace the world by the wall clock (flightctl run) instead of lock-step
    effects: tuple = ()             # sim: extensions of the plant (flightctl.sim.causes)
    noise: object = None            # sim: a SensorNoise; None: the default noise
    substeps: int | None = None     # sim: plant integration steps per loop period (None: the plant's SUBSTEPS)
    airframe: object = None         # sim: the plant's airframe where it is not the parameter file's
    devices: dict = field(default_factory=dict)   # pi, pi5: devices to use instead of opening them (the tests' fakes)
    link: str | None = None         # hil: serial:PATH[,BAUD] or tcp:[HOST:]PORT (flightctl.comms.link)


@dataclass
class Board:
    """An open board. `close()` leaves the motors at zero thrust and releases the devices."""
    hal: Hal
    name: str
    min_battery_v: float
    calibrate_s: float                                  # s sitting still before arming
    close: Callable[[], None] = lambda: None
    extra_columns: tuple[str, ...] = ()                 # log columns after the contract's
    extra_row: Callable[[], tuple] | None = None        # their values, once per loop
    meta: dict[str, str] = field(default_factory=dict)  # `# key: value` lines of the log
    world: object | None = None                         # the simulated world (true state); None on hardware


def missing_module(name: str, e: ModuleNotFoundError) -> Exception:
    """What to raise when board `name` cannot import a library: BoardUnavailable saying how to get
    it; our own module missing is a bug and stays itself."""
    if not e.name or e.name.split(".")[0] == "flightctl":
        return e
    install = BOARDS[name].install
    return BoardUnavailable(f"the {name} board needs the Python module {e.name!r}, which is not installed"
                            + (f" ({install})" if install else ""))


def _resolve(name: str, target: str):
    module, _, function = target.partition(":")
    try:
        return getattr(importlib.import_module(module), function)
    except ModuleNotFoundError as e:
        raise missing_module(name, e) from None


def _entry(name: str) -> Entry:
    if name not in BOARDS:
        raise InputError(f"unknown board {name!r} (known: {', '.join(BOARDS)})")
    return BOARDS[name]


def opener(name: str) -> Callable[[Params, BoardOptions], Board]:
    """The opener of a board; InputError for an unknown name, BoardUnavailable if its module cannot
    be imported here (a laptop has no pigpio)."""
    return _resolve(name, _entry(name).opener)


def described(*leave_out: str) -> str:
    """The boards for a --help text (but those named)."""
    return "; ".join(f"{name}: {entry.doc}" for name, entry in BOARDS.items() if name not in leave_out)


WIRED = ("pi", "pi5", "auto")    # the boards a --board-file wires


def check_options(name: str, board_file: str | None, link: str | None = None) -> None:
    """The board's own options, checked with the arguments (InputError, exit 2): a --board-file only
    for a board it wires, and a file that is there; --link for the hil board, which needs one, in a
    form `flightctl.comms.link.parse_link` reads. An option the board would ignore is refused, not
    ignored."""
    _entry(name)
    if board_file is not None:
        if name not in WIRED:
            raise InputError(f"--board-file {board_file}: the {name} board has no wiring file "
                             f"(--board-file goes with --board {', '.join(WIRED)})")
        if not os.path.isfile(board_file):
            raise InputError(f"--board-file {board_file}: no such file")
    if link is not None and name != "hil":
        raise InputError(f"--link {link}: the {name} board has no link (--link goes with --board hil)")
    if name == "hil":
        from flightctl.comms.link import parse_link
        if link is None:
            raise InputError("--board hil needs --link serial:/dev/serial0,921600 or tcp:HOST:PORT (docs/hil.md)")
        try:
            parse_link(link)
        except ValueError as e:
            raise InputError(str(e)) from None


def open_board(name: str, params: Params, options: BoardOptions = BoardOptions()) -> Board:
    return opener(name)(params, options)


def stop_motors(name: str, params: Params, options: BoardOptions = BoardOptions()) -> str:
    """Put the stop pulse on the board's ESCs whatever state a dead controller left them in; returns
    what was done (a board without ESCs has nothing to do)."""
    entry = _entry(name)
    if entry.stop_motors is None:
        return f"nothing to do on the {name} board"
    return _resolve(name, entry.stop_motors)(params, options)
