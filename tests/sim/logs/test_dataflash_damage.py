"""A DataFlash log damaged in place is read with a note of what was skipped (sim/logs/dataflash.py,
docs/log-import.md): the real ArduCopter 3.3 flight tests/data/ardupilot/log171.bin (CC BY-SA 3.0),
copied, with messages damaged at places drawn from a seeded generator, or the message at every 4 KB
as a worn card would: each damaged message is skipped whole, counted, and the log read on to its end.
Where the messages are comes from pymavlink's own index of the undamaged file."""
from __future__ import annotations

import re

import numpy as np
import pytest

from flightctl.sim.logs import each_log
from helpers.paths import DATA

DFReader = pytest.importorskip("pymavlink.DFReader")
LOG = DATA / "ardupilot" / "log171.bin"
KEEP = ("FMT", "FMTU", "UNIT", "MULT", "PARM")     # the log's own description: not damaged here


@pytest.fixture(scope="module")
def clean():
    """(the bytes, the messages' (offset, length) in file order, the types unused, the clean table)."""
    r = DFReader.DFReader_binary(str(LOG))
    msgs = sorted((o, r.formats[t].len, r.formats[t].name) for t, offs in enumerate(r.offsets)
                  if offs and t in r.formats for o in offs)
    (e,) = each_log(str(LOG))
    assert "damaged" not in e.table.meta.get("import_notes", "")
    unused = [t for t in range(256) if t not in r.formats]
    return LOG.read_bytes(), msgs, unused, e.table


def _candidates(data: bytes, msgs):
    """Messages whose damage is unambiguous: past the log's description, no header inside their body,
    and not next to another candidate (each damaged one is a place of its own)."""
    out = []
    for k in range(1, len(msgs) - 1):
        o, n, name = msgs[k]
        if name not in KEEP and o > len(data) // 10 and b"\xa3\x95" not in data[o + 2:o + n] and k % 3 == 0:
            out.append(k)
    return out


def _read(tmp_path, data: bytearray):
    path = tmp_path / "damaged.bin"
    path.write_bytes(bytes(data))
    (e,) = each_log(str(path))
    assert e.table is not None, e.reason
    m = re.search(r"damaged: (\d+) bytes in (\d+) places skipped", e.table.meta.get("import_notes", ""))
    assert m, e.table.meta.get("import_notes")
    return e.table, int(m[1]), int(m[2])


@pytest.mark.parametrize("seed", [171, 4096])
def test_messages_damaged_at_random_places_are_counted_and_the_log_read_on(tmp_path, clean, seed):
    data, msgs, unused, table = clean
    rng = np.random.default_rng(seed)
    cand = _candidates(data, msgs)
    hit = sorted(rng.choice(cand, size=int(rng.integers(10, 60)), replace=False))
    damaged = bytearray(data)
    kinds = rng.integers(0, 2, size=len(hit))
    for k, kind in zip(hit, kinds):
        o = msgs[k][0]
        if kind == 0:
            damaged[o:o + 2] = bytes(rng.integers(0, 0xA3, size=2).tolist())    # its header's two bytes
        else:
            damaged[o + 2] = int(rng.choice(unused))        # its type: one the log never defined
    t, skipped, places = _read(tmp_path, damaged)
    assert kinds.any() and not kinds.all()                 # both kinds drawn
    assert places == len(hit)
    assert skipped == sum(msgs[k][1] for k in hit)
    assert t["t"][-1] == pytest.approx(table["t"][-1], abs=0.05)      # read on to the end (the crash at 254 s)
    assert t["t"].size > 0.95 * table["t"].size


def test_a_log_damaged_every_4_kb_is_read_with_the_count(tmp_path, clean):
    """The header of the message at every 4,096th byte zeroed (where it is a whole message of the log's
    flight, as above)."""
    data, msgs, _, table = clean
    starts = np.array([o for o, _, _ in msgs])
    ok = set(_candidates(data, msgs)) | {k for k in range(len(msgs)) if msgs[k][2] not in KEEP and starts[k] > len(data) // 10}
    hit = []
    for b in range(4096, len(data), 4096):
        k = int(np.searchsorted(starts, b, side="right")) - 1
        o, n, name = msgs[k]
        if k in ok and b"\xa3\x95" not in data[o + 2:o + n] and (not hit or hit[-1] < k - 1):
            hit.append(k)
    damaged = bytearray(data)
    for k in hit:
        damaged[msgs[k][0]:msgs[k][0] + 2] = b"\0\0"
    t, skipped, places = _read(tmp_path, damaged)
    assert len(hit) > 500
    assert (places, skipped) == (len(hit), sum(msgs[k][1] for k in hit))
    assert t["t"][-1] == pytest.approx(table["t"][-1], abs=0.05)
