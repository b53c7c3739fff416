"""The one error type that reaches the user as a single line and exit status 2, and the checked
readers every input file goes through: regular files only (a FIFO is never opened blocking), UTF-8
text (a byte-order mark is dropped, UTF-16 and binary are refused), bounded line length, TOML."""
import math
import os
import stat
import tomllib
from pathlib import Path

MAX_LINE = 65536          # characters: a measured-data row is a few hundred; csv's own limit is 131072


class InputError(Exception):
    """Bad input (file, parameter, flag): the message names the file, row or column and what is wrong."""


def output_file(path, what: str = "", suffix: str | None = None) -> Path:
    """A file a command will write, checked before any work: its directory exists, it is not a
    directory, and (if given) it ends in `suffix`. `what`: the flag it came from, for the message."""
    p = Path(path)
    name = f"{what} {p}" if what else str(p)
    if suffix is not None and p.suffix.lower() != suffix:
        raise InputError(f"{name}: the output should end in {suffix}")
    if p.is_dir():
        raise InputError(f"{name}: is a directory, a file name is needed")
    if not p.resolve().parent.is_dir():
        raise InputError(f"{name}: the directory {p.resolve().parent} does not exist")
    return p


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a named pipe"),
                       (stat.S_ISSOCK, "a socket"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device")):
        if test(mode):
            return name
    return "not a regular file"


def read_bytes(path) -> bytes:
    """The bytes of a regular file. Opened non-blocking and checked with fstat before any read, so a
    named pipe or a device is refused without waiting on it."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as e:
        raise InputError(f"{path}: cannot read ({e.strerror})") from None
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise InputError(f"{path}: cannot read: {_kind(mode)}, a regular file is needed")
        with os.fdopen(fd, "rb", closefd=False) as f:
            return f.read()
    except OSError as e:
        raise InputError(f"{path}: cannot read ({e.strerror})") from None
    finally:
        os.close(fd)


def decode_text(path, data: bytes) -> str:
    """UTF-8 text (a leading byte-order mark is dropped); UTF-16/32 and binary files are refused."""
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise InputError(f"{path}: UTF-16 or UTF-32 text (byte-order mark {data[:2].hex(' ')}): save it as UTF-8")
    nul = data.find(b"\0")
    if nul >= 0:
        line = data.count(b"\n", 0, nul) + 1
        raise InputError(f"{path}: line {line}: a NUL byte: binary or UTF-16 data, UTF-8 text is needed")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = data.count(b"\n", 0, e.start) + 1
        raise InputError(f"{path}: line {line}: byte 0x{data[e.start]:02x} is not UTF-8 text") from None
    if len(text) > MAX_LINE:
        for lineno, line in enumerate(text.split("\n"), start=1):
            if len(line) > MAX_LINE:
                raise InputError(f"{path}: line {lineno}: {len(line)} characters long, at most {MAX_LINE}")
    return text


def read_text(path) -> str:
    """A regular file's text, checked as `decode_text` says."""
    return decode_text(path, read_bytes(path))


def read_toml(path, text: str | None = None) -> dict:
    """Parse a TOML file (or `text` under that name); a missing or malformed file is an InputError."""
    if text is None:
        text = read_text(Path(path))
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"{path}: not valid TOML ({e})") from None
    except RecursionError:
        raise InputError(f"{path}: not valid TOML (nested too deeply)") from None


def number(value) -> float | None:
    """A TOML value as a finite float, or None (a bool, text, a table, inf, nan, an integer beyond
    the float range)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    try:
        v = float(value)
    except OverflowError:
        return None
    return v if math.isfinite(v) else None
