"""`flightctl COMMAND ...`: one small module with a `main(argv)` per command.

Every command ends the same way: bad input is one line on stderr and exit 2 (`InputError`); Ctrl-C
is one line and exit 130 (worker processes are ended at once, a flight log is closed with a
`# partial:` line); output piped into a reader that stops early (`| head`, the help and the version
too) is dropped quietly and the command finishes its work and exits with its own status; a home that
cannot be written adds no line (`matplotlib_home`)."""
from __future__ import annotations

import atexit
import importlib
import os
import shutil
import signal
import sys
import tempfile
import threading
from contextlib import contextmanager

from flightctl.errors import InputError

EXIT_INTERRUPTED = 130          # 128 + SIGINT, what a shell reports for a command ended by Ctrl-C

COMMANDS = {
    "sim": ("flightctl.sim.cli", "fly the onboard control code against the simulated quadcopter"),
    "identify": ("flightctl.sim.identify.cli", "fit the paper's models to bench, yaw-drag, pendulum or rotor data; real-data report"),
    "diagnose": ("flightctl.sim.diagnose.cli", "name what the model gets wrong in flight logs"),
    "run": ("flightctl.service.run", "the onboard service: fly on the quadcopter (or --board sim)"),
    "bench": ("flightctl.hil.bench", "spin one motor at a time for identification"),
    "hil": ("flightctl.hil.cli", "hardware-in-the-loop: the PC side (serve), or both ends on one machine (demo)"),
    "analyze": ("flightctl.sim.analysis.cli", "linear analysis of each loop about hover: margins, damping, steps"),
    "tune": ("flightctl.sim.sweeps.tune", "the paper's PID tuning procedure (sec. 3.3), automated on the model"),
    "params": ("flightctl.sim.paramscli", "parameter files: params show [NAME|FILE], params diff A B"),
    "log": ("flightctl.sim.logs.export", "flight logs: log export F.csv F.ulg (PX4's ULog), log import "
                                         "FOREIGN_LOG OUT.csv (a PX4, ArduPilot, Betaflight or INAV log)"),
}

EXIT_CODES = (  # what every command's exit status means (a command's --help says which it uses)
    (0, "done (the vehicle flew and landed, the fit or the report was written)"),
    (1, "done, and the answer is no: a crash, a vehicle that did not fly, a bench run whose thrust fell, "
        "two parameter files that differ"),
    (2, "bad input: one line on stderr naming the file, row or flag; nothing written"),
    (3, "cannot fly here: the board or its devices could not be opened (a named reason)"),
    (EXIT_INTERRUPTED, "interrupted (Ctrl-C): the motors stopped, workers ended, a flight log kept as partial"),
)


def usage() -> str:
    lines = ["usage: flightctl COMMAND [ARGS]  (flightctl COMMAND --help for more)", "", "commands:"]
    lines += [f"  {name:<9} {doc}" for name, (_, doc) in COMMANDS.items()]
    lines += ["", "exit codes:"] + [f"  {code:<9} {doc}" for code, doc in EXIT_CODES]
    return "\n".join(lines)


def version() -> str:
    """`flightctl --version`: this package's version, Python's, and which simulator `flightctl sim` flies
    (compiled by numba, or plain Python), read from the installed packages' metadata without importing them."""
    from importlib import metadata

    from flightctl import __version__
    try:
        world = f"the compiled simulator (numba {metadata.version('numba')})"
        if os.environ.get("FLIGHTCTL_JIT", "1") == "0":
            world = "the plain-Python simulator (FLIGHTCTL_JIT=0; numba installed)"
    except metadata.PackageNotFoundError:
        world = "the plain-Python simulator (numba is not installed)"
    return (f"flightctl {__version__} (Python {sys.version.split()[0]}, numpy {metadata.version('numpy')}; "
            f"{world}) from {os.path.dirname(os.path.abspath(__file__))}")


def command_name(argv: list[str], module=None) -> str:
    """`flightctl COMMAND`, or `flightctl COMMAND SUB` for a command whose module lists its SUBCOMMANDS."""
    if module is not None and len(argv) > 1 and argv[1] in getattr(module, "SUBCOMMANDS", ()):
        return f"flightctl {argv[0]} {argv[1]}"
    return f"flightctl {argv[0]}"


def interrupted(e: BaseException) -> bool:
    """Whether `e` is Ctrl-C: a KeyboardInterrupt, or an error raised because one arrived inside a
    compiled function (numba reports it as a SystemError caused by the KeyboardInterrupt)."""
    seen = set()
    while e is not None and id(e) not in seen:
        if isinstance(e, KeyboardInterrupt):
            return True
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return False


@contextmanager
def ctrl_c_sets(event: threading.Event):
    """While the block runs, Ctrl-C sets `event` (a flight ends at its next loop period and closes its
    log); a second Ctrl-C interrupts at once. Outside the main thread, nothing changes."""
    if threading.current_thread() is not threading.main_thread():
        yield event
        return

    def handler(signum, frame):
        if event.is_set():
            raise KeyboardInterrupt
        event.set()
    previous = signal.signal(signal.SIGINT, handler)
    try:
        yield event
    finally:
        signal.signal(signal.SIGINT, previous)


class PipeSafe:
    """stdout or stderr, where a reader that went away (`flightctl sim ... | head`) ends the output,
    not the command: the rest is written to /dev/null and the command finishes its work."""

    def __init__(self, stream):
        self._stream = stream
        self.broken = False

    def _gone(self) -> None:
        self.broken = True
        try:                             # what the stream still buffers goes nowhere, now and at exit
            null = os.open(os.devnull, os.O_WRONLY)
            os.dup2(null, self._stream.fileno())
            os.close(null)
        except (OSError, ValueError, AttributeError):
            pass

    def write(self, text):
        if not self.broken:
            try:
                return self._stream.write(text)
            except BrokenPipeError:
                self._gone()
        return len(text)

    def flush(self):
        if not self.broken:
            try:
                self._stream.flush()
            except BrokenPipeError:
                self._gone()

    def __getattr__(self, name):
        return getattr(self._stream, name)


def _writable_or_makeable(folder: str) -> bool:
    """Whether `folder` is a directory this user may write, or could be made (its nearest existing parent is)."""
    path = os.path.abspath(folder)
    while not os.path.exists(path) and os.path.dirname(path) != path:
        path = os.path.dirname(path)
    return os.path.isdir(path) and os.access(path, os.W_OK | os.X_OK)


def matplotlib_home() -> None:
    """matplotlib's config and cache folders (MPLCONFIGDIR, else ~/.config/matplotlib and ~/.cache/matplotlib,
    XDG's variables first) where this user's home cannot hold them (a service user, HOME=/nonexistent): a
    private temporary folder, removed at exit, set before matplotlib's import, which otherwise writes
    two warning lines on every command (a third-party import such as python-control's pulls it in too:
    `main` sets it before the command's import). Its font cache is then rebuilt in each such process."""
    if os.environ.get("MPLCONFIGDIR"):
        return
    home = os.path.expanduser("~")
    folders = [os.path.join(os.environ.get(var) or os.path.join(home, sub), "matplotlib")
               for var, sub in (("XDG_CONFIG_HOME", ".config"), ("XDG_CACHE_HOME", ".cache"))]
    if all(_writable_or_makeable(f) for f in folders):
        return
    folder = tempfile.mkdtemp(prefix="flightctl-matplotlib-")
    os.environ["MPLCONFIGDIR"] = folder
    atexit.register(shutil.rmtree, folder, ignore_errors=True)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    saved = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = PipeSafe(sys.stdout), PipeSafe(sys.stderr)   # the help and the version too
    try:
        return _command(argv)
    finally:
        for stream in (sys.stdout, sys.stderr):
            if isinstance(stream, PipeSafe):
                stream.flush()
        sys.stdout, sys.stderr = saved


def _command(argv: list[str]) -> int:
    if not argv or argv[0] in ("-h", "--help"):
        print(usage())
        return 0
    if argv[0] in ("-V", "--version"):
        print(version())
        return 0
    if argv[0] not in COMMANDS:
        print(f"flightctl: unknown command {argv[0]!r} (commands: {', '.join(COMMANDS)}; flightctl --help)",
              file=sys.stderr)
        return 2
    matplotlib_home()
    module = None
    try:
        module = importlib.import_module(COMMANDS[argv[0]][0])
        return int(module.main(argv[1:]) or 0)
    except InputError as e:
        print(f"{command_name(argv, module)}: error: {e}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, SystemError) as e:
        if not interrupted(e):
            raise
        print(f"{command_name(argv, module)}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    sys.exit(main())
