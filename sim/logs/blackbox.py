"""The blackbox format (`.bbl`, `.bfl`, `.BFL`, INAV's `.TXT`; Betaflight, INDIflight, INAV) through
orangebox 0.4.0, one log at a time (docs/log-import.md has each field, unit and frame with its
evidence; `bbfields` turns one log's frames into this project's streams).

A file holds one log per arming, each starting with its own `H Product:Blackbox` header. Each log is
cut out at its header and handed to orangebox alone, so an empty or damaged log never takes the
others with it: a log with a header and no frames (armed and disarmed at once) is skipped with that
reason, and one whose frames stop decoding (a file cut by a crash or a power loss, damaged bytes) is
read up to the damage, as Blackbox Explorer does, with a note naming the byte.
"""
from __future__ import annotations

import contextlib
import io
import math
import os
import tempfile

import numpy as np

from flightctl.errors import InputError
from flightctl.sim.logs.common import parser_said

MAGIC = b"H Product:Blackbox flight data recorder"
LOG_END = b"E\x0f"                 # the end-of-log event: all a header-only log holds after its header
TAIL_SLACK = 64                    # bytes: damage this close to the end is the end of the log
MIN_FRAMES = 10
BAD_FRAMES_QUIET, BAD_FRAMES_SHARE = 10, 0.001   # undecoded frames named when more than these


def split(data: bytes) -> list[tuple[int, int]]:
    """(start, end) of each log in a blackbox file: from one header to the next."""
    starts = []
    k = data.find(MAGIC)
    while k >= 0:
        starts.append(k)
        k = data.find(MAGIC, k + len(MAGIC))
    return list(zip(starts, starts[1:] + [len(data)]))


def header_end(chunk: bytes) -> int:
    """The length of a log's header: its lines that start with 'H '."""
    pos = 0
    while chunk.startswith(b"H ", pos):
        nl = chunk.find(b"\n", pos)
        if nl < 0:
            return len(chunk)
        pos = nl + 1
    return pos


def frameless(chunk: bytes) -> str | None:
    """Why a log holds no frames (None when it may hold some): the bytes after its header."""
    rest = chunk[header_end(chunk):].rstrip(b"\xff")          # erased flash reads 0xff
    if not rest or rest.startswith(LOG_END):
        return "header only: armed and disarmed at once, no frames"
    if b"I" not in rest:
        return "no main frame after the header"
    return None


def _quiet():
    stack = contextlib.ExitStack()
    stack.enter_context(contextlib.redirect_stdout(io.StringIO()))
    stack.enter_context(contextlib.redirect_stderr(io.StringIO()))
    return stack


def _parser(name: str, chunk: bytes):
    """orangebox's parser of one log, given alone (its own file: orangebox reads paths); a header it
    cannot read is one line naming the log (`name`) and what orangebox said of it."""
    try:
        from orangebox import Parser
    except ImportError:
        raise InputError(f"{name}: reading a blackbox log needs the logs extra: pip install '.[logs]' "
                         "(from the checkout)") from None
    fd, tmp = tempfile.mkstemp(suffix=".bbl")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(chunk)
        with _quiet():
            return Parser.load(tmp, 1)          # reads the header and every frame's bytes
    except Exception as e:                      # orangebox raises what a garbled header gives it
        raise InputError(f"{name}: its header is garbled ({parser_said(e)})") from None
    finally:
        os.unlink(tmp)


def frames(parser, offset: int, size: int) -> tuple[list[str], np.ndarray, list[str]]:
    """The main frames as a float array (n, fields; a text field is NaN), and notes: frames that did
    not decode, and where the decoding stopped when it did before the end (byte offsets in the file:
    `offset` is where the frames start, `size` the bytes of the file)."""
    names = list(parser.field_names)
    width = len(names)
    rows, notes = [], []
    with _quiet():
        try:
            for frame in parser.frames():
                data = frame.data
                if len(data) == width:
                    rows.append([v if isinstance(v, (int, float)) else math.nan for v in data])
        except Exception as e:                 # orangebox raises what the bytes give it
            pos = offset + parser.reader.tell()
            if "End of log" in str(e):         # INAV's end-of-log event carries text orangebox does not know
                pass
            elif pos >= size - TAIL_SLACK:
                notes.append(f"the file ends inside a frame at byte {pos} (cut short: a crash or a power loss): "
                             f"read up to there")
            else:
                notes.append(f"damaged from byte {pos} of {size} ({parser_said(e)}): read up to there")
    ctx = getattr(parser, "_ctx", None)
    bad = getattr(ctx, "invalid_frame_count", 0) if ctx is not None else 0
    if bad > max(BAD_FRAMES_QUIET, BAD_FRAMES_SHARE * len(rows)):      # (a few at events and the end are usual)
        notes.append(f"{bad} frames that did not decode skipped (orangebox resynchronises on the next frame)")
    return names, np.array(rows, dtype=float).reshape(len(rows), width), notes


def read(path: str, chunk: bytes, offset: int, size: int, name: str):
    """One log of the blackbox file `path` (its bytes `chunk`, at `offset` in a file of `size` bytes;
    `name` the log's in messages) as an `Imported`, or InputError naming why it cannot be read."""
    from flightctl.sim.logs import bbfields
    why = frameless(chunk)
    if why:
        raise InputError(f"{name}: {why}")
    parser = _parser(name, chunk)
    names, a, notes = frames(parser, offset + header_end(chunk), size)
    if a.shape[0] < MIN_FRAMES:
        raise InputError(f"{name}: {a.shape[0]} main frames: " + ("; ".join(notes) or "no flight in it"))
    return bbfields.imported(name, dict(parser.headers), names, a, notes)
