"""The checked readers every input file goes through: regular files only (a FIFO is never opened
blocking), UTF-8 text (a byte-order mark is dropped, UTF-16 and binary are refused), bounded line
length, TOML. The outputs: checked before any work (`output_file`, `output_dir`, `output_room`), written
whole or not at all (`write_atomic`: a temporary name in the same folder, then a rename). Every refusal
is an InputError (flightctl/errors.py)."""
import os
import secrets
import stat
import tomllib
from pathlib import Path

from flightctl.errors import InputError

MAX_LINE = 65536          # characters: a measured-data row is a few hundred; csv's own limit is 131072


def output_file(path, what: str = "", suffix: str | None = None) -> Path:
    """A file a command will write, checked before any work: its directory exists and this process
    may create files in it (`write_atomic` writes a temporary name there, then renames), it is not a
    directory, an existing file there is one this user may write, and (if given) it ends in `suffix`.
    `what`: the flag it came from, for the message."""
    p = Path(path)
    name = f"{what} {p}" if what else str(p)
    if p.is_dir():
        raise InputError(f"{name}: is a directory, a file name is needed")
    if suffix is not None and p.suffix.lower() != suffix:
        raise InputError(f"{name}: the output should end in {suffix}")
    folder = p.resolve().parent
    if not folder.is_dir():
        raise InputError(f"{name}: the directory {folder} does not exist")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError(f"{name}: the directory {folder} is not writable by this user")
    if p.exists() and not os.access(p, os.W_OK):
        raise InputError(f"{name}: the file exists and is not writable by this user")
    return p


def output_prefix(prefix: str, what: str = "--plot") -> str:
    """A file-name prefix a command writes PREFIX-NAME.png files from (each then checked by
    `output_file`): it must end in a name, not in a folder (`dir/` would write `dir/-bode.png`)."""
    if not prefix or prefix.endswith(("/", os.sep)) or os.path.isdir(prefix):
        raise InputError(f"{what} {prefix}: a file-name prefix is needed (PREFIX-NAME.png), not a directory")
    return prefix


def output_room(path, need: float, what: str = "", why: str = "") -> Path:
    """A folder (or a file's folder) checked for `need` bytes free on its disk before a run that
    writes them (a flight's log, found full only after the flight otherwise). `why`: how `need` was
    estimated, for the message."""
    p = Path(path).resolve()
    first = p
    while not first.is_dir() and first != first.parent:
        first = first.parent
    try:
        st = os.statvfs(first)
    except (OSError, AttributeError):      # no statvfs (Windows) or it cannot be asked: not checked
        return Path(path)
    free = st.f_bavail * st.f_frsize
    if free < need:
        name = f"{what} {path}" if what else str(path)
        raise InputError(f"{name}: {free / 1e6:.1f} MB free on its disk, {need / 1e6:.1f} MB needed"
                         + (f" ({why})" if why else ""))
    return Path(path)


def output_dir(path, what: str = "") -> Path:
    """A directory a command will write into, checked before any work (and not made yet): it is a
    directory this process may create files in, or its nearest existing parent is one."""
    p = Path(path)
    name = f"{what} {p}" if what else str(p)
    first = p.resolve()
    while not first.exists() and first != first.parent:
        first = first.parent
    if not first.is_dir():
        raise InputError(f"{name}: {first} is not a directory")
    if not os.access(first, os.W_OK | os.X_OK):
        where = "the directory" if first == p.resolve() else f"{first}, where it would be made,"
        raise InputError(f"{name}: {where} is not writable by this user")
    return p


def temporary_beside(path) -> Path:
    """A new, empty file in `path`'s folder (so that a rename onto `path` is atomic), named after it,
    with the permissions a plain new file gets (the umask's)."""
    p = Path(path)
    folder = p.resolve().parent
    for _ in range(100):
        tmp = folder / f".{p.name}.{secrets.token_hex(4)}.part"
        try:
            os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
            return tmp
        except FileExistsError:
            continue
    raise FileExistsError(f"{folder}: no free temporary name for {p.name}")


def write_atomic(path, data) -> Path:
    """Write a whole output file: into a temporary name in the same folder, then renamed onto `path`,
    so that a reader (or a second run writing the same file) never sees it half-written, and a full
    disk leaves the old file (or none), never a truncated one. OSError is raised as an InputError.
    `data`: str, bytes, or an iterable of str written piece by piece (a file too large to hold)."""
    p = Path(path)
    tmp = None
    try:
        tmp = temporary_beside(p)
        with open(tmp, "wb") as f:
            for piece in ([data] if isinstance(data, (str, bytes)) else data):
                f.write(piece.encode() if isinstance(piece, str) else piece)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, p)
        tmp = None
    except OSError as e:
        raise InputError(f"{p}: cannot write ({e.strerror or e})") from None
    finally:
        if tmp is not None:
            try:
                os.unlink(tmp)
            except OSError:
                pass
    return p


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a named pipe"),
                       (stat.S_ISSOCK, "a socket"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device")):
        if test(mode):
            return name
    return "not a regular file"


def read_bytes(path, limit: int | None = None) -> bytes:
    """The bytes of a regular file (its first `limit` when given). Opened non-blocking and checked with
    fstat before any read, so a named pipe or a device is refused without waiting on it."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as e:
        raise InputError(f"{path}: cannot read ({e.strerror})") from None
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise InputError(f"{path}: cannot read: {_kind(mode)}, a regular file is needed")
        with os.fdopen(fd, "rb", closefd=False) as f:
            return f.read() if limit is None else f.read(limit)
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
