"""`flightctl params`: read parameter files (flightctl/params.py) as a person would.

    flightctl params show [NAME|FILE] [--gains table6|table4]     (shipped NAMEs: flightctl params show --help)
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

from flightctl.errors import Parser
from flightctl.params import GAIN_SETS, Params, dumps, load, resolve, shipped
from flightctl.sim.causes import load_vehicle

DEFAULTS = "defaults"
TABLES = ("airframe", "gains", "filters", "sensors")


def _read(spec: str | None, gains: str | None) -> Params:
    """The parameters with the source of each value (flightctl/params.py: `Params.sources`)."""
    chosen = GAIN_SETS[gains] if gains else None
    if spec is None or spec == DEFAULTS:
        return load(None, chosen)
    return load_vehicle(resolve(spec), chosen)


def _origin(params: Params) -> str:
    return params.origin or DEFAULTS


def show(spec: str | None, gains: str | None = None) -> str:
    params = _read(spec, gains)
    given = dict(params.sources)
    unset = "default" if not params.origin else "default (not in the file)"
    full = {f.name: given.get(f.name) or f"{unset}: {params.source(f.name)}"
            for t in TABLES for f in dataclasses.fields(getattr(params, t))}
    which = f"gains {gains} (--gains)" if gains else "gains: the file's [gains], else table6"
    head = f"# flightctl params show: {_origin(params)}; {which}\n"
    return head + dumps(params, full)


def _flat(params: Params) -> dict[str, tuple[float, str]]:
    out = {}
    for t in TABLES:
        for f in dataclasses.fields(getattr(params, t)):
            key = f.name if t == "airframe" else f"{t}.{f.name}"
            out[key] = (getattr(getattr(params, t), f.name), f.metadata["unit"])
    return out


def diff(a: str, b: str, gains: str | None = None) -> list[str]:
    """One line per difference; empty when A and B are the same parameter set."""
    pa, pb = _read(a, gains), _read(b, gains)
    oa, ob = _origin(pa), _origin(pb)
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


SUBCOMMANDS = ("show", "diff")          # an error names `flightctl params show` (flightctl/cli.py)


def main(argv: list[str]) -> int:
    p = Parser(prog="flightctl params", description=__doc__.split("\n\n")[0],
                epilog=__doc__.split("\n\n", 2)[2], formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="action", required=True)
    s = sub.add_parser("show", help="print a full parameter file with units and sources")
    s.add_argument("spec", nargs="?", metavar="NAME|FILE",
                   help=f"a shipped vehicle ({', '.join(shipped())}) or a file (default: the defaults)")
    d = sub.add_parser("diff", help="the differences between two parameter sets")
    d.add_argument("a", metavar="A", help="a parameter file or a shipped name")
    d.add_argument("b", metavar="B", help="the other")
    for q in (s, d):
        q.add_argument("--gains", choices=sorted(GAIN_SETS),
                       help="a gain set by name, which replaces the file's [gains] (default: the file's, else table6)")
    args = p.parse_args(argv)
    if args.action == "show":
        print(show(args.spec, args.gains), end="")
        return 0
    lines = diff(args.a, args.b, args.gains)
    print("\n".join(lines) if lines else f"{args.a} and {args.b}: the same parameters")
    return 1 if lines else 0
