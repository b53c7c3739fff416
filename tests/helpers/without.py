"""`flightctl ARGS` in a fresh interpreter in which some modules cannot be imported, as on a machine
where they are not installed (a laptop has no pigpio, spidev or smbus2)."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

PI_LIBRARIES = ("pigpio", "spidev", "smbus2")


def run_without(modules: tuple[str, ...], args: list[str], cwd: Path, env: dict | None = None):
    """No timeout: the child is waited for, however busy the machine (each command ends by itself)."""
    code = ("import sys\n"
            f"for name in {list(modules)!r}:\n"
            "    sys.modules[name] = None     # import raises ModuleNotFoundError, as if not installed\n"
            "from flightctl.cli import main\n"
            f"sys.exit(main({list(args)!r}))\n")
    return subprocess.run([sys.executable, "-c", code], cwd=cwd, capture_output=True, text=True, env=env)
