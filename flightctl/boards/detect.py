"""Which Raspberry Pi this is, from the device tree's model string, and the registry's openers that
depend on it: `--board pi` refuses on a Raspberry Pi 5 (pigpiod does not run there), and `--board auto`
(the default of `flightctl run`, and the systemd unit's) opens `pi5` on a Raspberry Pi 5 and `pi`
anywhere else.

    /sys/firmware/devicetree/base/model:  "Raspberry Pi 5 Model B Rev 1.0\\0", "Raspberry Pi 4 Model B Rev 1.4\\0", ...

The model is read from sysfs first: /proc/device-tree is only a symlink into it, and the service's
sandbox (ProcSubset=pid in systemd/flightctl.service) mounts a procfs that has nothing but the process
directories, so /proc/device-tree does not exist there (tests/onboard/boards/test_detect_sandbox.py). /proc/device-tree is
the fallback for a system whose sysfs is not mounted where it is expected.

The RP1 I/O chip (its PWM, its GPIO) is on the Raspberry Pi 5, the Pi 500 and the Compute Module 5;
their model strings start "Raspberry Pi 5", "Raspberry Pi 500" and "Raspberry Pi Compute Module 5".
"""
from __future__ import annotations

from flightctl.boards import Board, BoardOptions, BoardUnavailable, missing_module, open_board, stop_motors
from flightctl.params import Params

MODEL_PATHS = ("/sys/firmware/devicetree/base/model", "/proc/device-tree/model")
RP1_MODELS = ("Raspberry Pi 5", "Raspberry Pi Compute Module 5")     # "Raspberry Pi 5" covers the 500


def model(paths: tuple[str, ...] | None = None) -> str:
    """The board's model string, from the first of `paths` (MODEL_PATHS) that can be read; "" where
    there is no device tree (a PC)."""
    for path in MODEL_PATHS if paths is None else paths:
        try:
            with open(path, "rb") as f:
                return f.read().rstrip(b"\0\n").decode(errors="replace")
        except OSError:
            continue
    return ""


def is_pi5(name: str | None = None) -> bool:
    name = model() if name is None else name
    return name.startswith(RP1_MODELS)


def detected() -> str:
    """The board `auto` stands for here."""
    return "pi5" if is_pi5() else "pi"


def refuse_on_pi5() -> None:
    """`BoardUnavailable` on a Raspberry Pi 5: pigpio cannot drive it."""
    name = model()
    if is_pi5(name):
        raise BoardUnavailable(f"this is a {name}: pigpio does not run on it (pigpiod refuses the board); "
                               "use --board pi5 (docs/pi.md, \"Raspberry Pi 5\")")


# --- the registry's openers ----------------------------------------------------------------------
def _pigpio_board():
    refuse_on_pi5()
    try:
        from flightctl.boards import pi
    except ModuleNotFoundError as e:        # pigpio: the `pi` extra
        raise missing_module("pi", e) from None
    return pi


def open_pi(params: Params, options: BoardOptions) -> Board:
    return _pigpio_board().open_board(params, options)


def stop_pi(params: Params, options: BoardOptions) -> str:
    return _pigpio_board().stop_motors(params, options)


def open_auto(params: Params, options: BoardOptions) -> Board:
    return open_board(detected(), params, options)


def stop_auto(params: Params, options: BoardOptions) -> str:
    return stop_motors(detected(), params, options)
