"""`flightctl params`: read parameter files (flightctl/params.py) as a person would.

    flightctl params show [NAME|FILE] [--gains table6|table4]
    flightctl params diff A B [--gains ...]

`show` prints the full parameter file, every key with its unit and where its value comes from: the
defaults (the schema's source, e.g. "paper, Table 2"), a shipped vehicle (`paper-as-flown`) or a
file, with the file's own comment when it has one. The output is itself a valid parameter file.
`diff` prints the keys whose values differ, with units, and the effects one side has and the other
lacks; exit status 0 when the two are the same, 1 when they differ (as diff(1)), 2 on bad input.
A or B may be `defaults`, a shipped vehicle's name or a file.
"""
from __future__ import annotations

import argparse
import dataclasses
import re
from pathlib import Path

from flightctl.errors import InputError, read_text, read_toml
from flightctl.params import GAIN_SETS, VEHICLES, Params, dumps, load, resolve
from flightctl.sim.causes import load_vehicle

DEFAULTS = "defaults"
TABLES = ("airframe", "gains", "filters", "sensors")
_LINE = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*=[^#]*#\s*(.*)$")


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        raise InputError(message)


def _read(spec: str | None, gains: str) -> tuple[Params, dict[str, str], str]:
    """The parameters, the source of each key the file sets, and how to name where they came from."""
    if spec is None or spec == DEFAULTS:
        return load(None, GAIN_SETS[gains]), {}, "defaults"
    path = resolve(spec)
    params = load_vehicle(path, GAIN_SETS[gains])
    origin = f"vehicle {path.stem}" if path.parent == VEHICLES else f"file {path}"
    keys = {f.name for t in TABLES for f in dataclasses.fields(getattr(params, t))}
    sources = {}
    for line in read_text(path).splitlines():
        m = _LINE.match(line)
        if m and m.group(1) in keys:
            note = m.group(2).split(";", 1)[-1].strip()
            sources[m.group(1)] = f"{origin}: {note}" if note else origin
    for key in _keys_set(path) - set(sources):
        sources[key] = origin
    return params, sources, origin


def _keys_set(path: Path) -> set[str]:
    data = read_toml(path)
    out = {k for k, v in data.items() if not isinstance(v, (dict, list))}
    for table in ("gains", "filters", "sensors"):
        out |= set(data.get(table, {})) - {"preset", "range"}
    return out


def show(spec: str | None, gains: str = "table6") -> str:
    params, sources, origin = _read(spec, gains)
    unset = "default" if origin == "defaults" else "default (not in the file)"
    full = {}
    for t in TABLES:
        for f in dataclasses.fields(getattr(params, t)):
            default = f.metadata["source"] if (t, gains) != ("gains", "table4") else "paper, Table 4 (--gains table4)"
            full[f.name] = sources.get(f.name, f"{unset}: {default}")
    head = f"# flightctl params show: {origin}; gains {gains} where the file sets none\n"
    return head + dumps(params, full)


def _flat(params: Params) -> dict[str, tuple[float, str]]:
    out = {}
    for t in TABLES:
        for f in dataclasses.fields(getattr(params, t)):
            key = f.name if t == "airframe" else f"{t}.{f.name}"
            out[key] = (getattr(getattr(params, t), f.name), f.metadata["unit"])
    return out


def diff(a: str, b: str, gains: str = "table6") -> list[str]:
    """One line per difference; empty when A and B are the same parameter set."""
    pa, _, oa = _read(a, gains)
    pb, _, ob = _read(b, gains)
    fa, fb = _flat(pa), _flat(pb)
    lines = []
    for key, (va, unit) in fa.items():
        vb = fb[key][0]
        if va != vb:
            change = f" ({(vb - va) / va:+.1%})" if va else ""
            lines.append(f"{key}: {va!r} -> {vb!r} {unit}{change}")
    ea, eb = set(pa.effects), set(pb.effects)
    for sign, effects in (("-", ea - eb), ("+", eb - ea)):
        for e in sorted(effects, key=lambda e: (e.cause, e.parameters)):
            values = ", ".join(f"{k}={v!r}" for k, v in e.parameters)
            lines.append(f"{sign} effect {e.cause}({values})" + (f"  # {e.source}" if e.source else ""))
    return [f"--- {oa}", f"+++ {ob}"] + lines if lines else []


def main(argv: list[str]) -> int:
    p = _Parser(prog="flightctl params", description=__doc__.split("\n\n")[0],
                epilog=__doc__.split("\n\n", 2)[2], formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="action", required=True)
    s = sub.add_parser("show", help="print a full parameter file with units and sources")
    s.add_argument("spec", nargs="?", metavar="NAME|FILE", help="a shipped vehicle or a file (default: the defaults)")
    d = sub.add_parser("diff", help="the differences between two parameter sets")
    d.add_argument("a", metavar="A", help="a parameter file or a shipped name")
    d.add_argument("b", metavar="B", help="the other")
    for q in (s, d):
        q.add_argument("--gains", choices=sorted(GAIN_SETS), default="table6",
                       help="the gain set a file without [gains] uses (default table6)")
    args = p.parse_args(argv)
    if args.action == "show":
        print(show(args.spec, args.gains), end="")
        return 0
    lines = diff(args.a, args.b, args.gains)
    print("\n".join(lines) if lines else f"{args.a} and {args.b}: the same parameters")
    return 1 if lines else 0
