"""`flightctl COMMAND ...`: one small module with a `main(argv)` per command."""
from __future__ import annotations

import importlib
import sys

from flightctl.errors import InputError

COMMANDS = {
    "sim": ("flightctl.sim.cli", "fly the onboard control code against the simulated quadcopter"),
    "identify": ("flightctl.sim.identify.cli", "fit the paper's models to bench, yaw-drag, pendulum or rotor data; real-data report"),
    "diagnose": ("flightctl.sim.identify.diagnose.cli", "name what the model gets wrong in flight logs"),
    "run": ("flightctl.service", "the onboard service: fly on the quadcopter (or --board sim)"),
    "bench": ("flightctl.hil.bench", "spin one motor at a time for identification"),
    "hil": ("flightctl.hil.cli", "hardware-in-the-loop: the PC side (serve), or both ends on one machine (demo)"),
    "analyze": ("flightctl.sim.analysis.cli", "linear analysis of each loop about hover: margins, damping, steps"),
    "tune": ("flightctl.sim.sweeps.tune", "the paper's PID tuning procedure (sec. 3.3), automated on the model"),
    "params": ("flightctl.sim.paramscli", "parameter files: params show [NAME|FILE], params diff A B"),
    "log": ("flightctl.sim.logs.export", "flight log tools: log export F.csv F.ulg (PX4's ULog)"),
}


def usage() -> str:
    lines = ["usage: flightctl COMMAND [ARGS]  (flightctl COMMAND --help for more)", "", "commands:"]
    lines += [f"  {name:<9} {doc}" for name, (_, doc) in COMMANDS.items()]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(usage())
        return 0
    if argv[0] in ("-V", "--version"):
        from flightctl import __version__
        print(__version__)
        return 0
    if argv[0] not in COMMANDS:
        print(f"flightctl: unknown command {argv[0]!r}\n{usage()}", file=sys.stderr)
        return 2
    module = importlib.import_module(COMMANDS[argv[0]][0])
    try:
        return int(module.main(argv[1:]) or 0)
    except InputError as e:
        print(f"flightctl {argv[0]}: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
