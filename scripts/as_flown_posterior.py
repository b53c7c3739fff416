"""The paper's vehicle as its own flights say it was (issue 44): paper-as-flown's ranges conditioned on
the paper's evidence by rejection ABC on the batched simulator (sim/sweeps/posterior.py, the evidence
sim/sweeps/evidence.py), each term's Bayes factor, and the posterior's parameter file.

    python scripts/as_flown_posterior.py [--n 16000] [--n-off 1500] [--seed 44] [--workers 2]
        fly the prior's draws and each model without one term (and with each candidate), write
        docs/as-flown-posterior.json, flightctl/vehicles/paper-posterior.toml and the docs blocks
    python scripts/as_flown_posterior.py --from docs/as-flown-posterior.json [--doc DOC] [--readme README]
        render the blocks from a run's JSON (scripts/docs.py; tests/project/test_docs.py checks them)

Everything the blocks say is computed here from the JSON's per-draw values and verdicts (the prior's
run) and the other models' counts: the shares with their Monte Carlo errors, the marginals, the held-out
table and the Bayes factors.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from flightctl.sim.docs import marked, table, write_or_exit
from flightctl.sim.sweeps import evidence, posterior

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "as-flown.md"
README = ROOT / "README.md"
JSON = ROOT / "docs" / "as-flown-posterior.json"
VEHICLE = ROOT / "flightctl" / "vehicles" / "paper-posterior.toml"
PRIOR = "paper-as-flown"
DOC_MARKS = marked("as-flown posterior")
README_MARKS = marked("paper facts posterior")


def run(n: int, n_off: int, seed: int, workers: int, terms=posterior.TERMS, candidates=posterior.CANDIDATES,
        progress: bool = True) -> dict:
    """Fly the prior and the other models; the JSON-ready result."""
    from flightctl.sim import causes
    from flightctl.sim.progress import Progress
    prior = causes.load_vehicle(PRIOR)
    models = [("prior", prior, "flight", n)] + [(f"without {t}", posterior.without(prior, t), "flight", n_off)
                                                for t in terms] + \
        [(f"with {name}", prior, structure, n_off) for name, structure, _ in candidates]
    bar = Progress(sum(m[3] for m in models), "posterior ") if progress else None
    out, start = {"prior": PRIOR, "seed": seed, "models": {}}, time.time()
    for name, params, structure, size in models:
        tick = (lambda f, s=size, nm=name: bar.update(f, nm, items=s)) if bar else None
        r = posterior.fly(params, size, seed, structure, workers, tick)
        if bar:
            bar.step(name, size)
        out["models"][name] = posterior.counts(r)
        if name == "prior":
            out["draws"] = {f"{c}.{p}": [float(f"{x:.6g}") for x in v] for (c, p), v in r["draws"].items()}
            out["verdicts"] = {i: "".join("1" if x else "0" for x in v) for i, v in r["verdicts"].items()}
    out["seconds"] = round(time.time() - start)
    return out


def analyse(result: dict) -> dict:
    """The figures the blocks show, from the JSON."""
    draws, verdicts = posterior.stored(result)
    ok = evidence.passes(verdicts)
    n, k = len(ok), int(ok.sum())
    m = result["models"]
    factors = []
    for name, c in m.items():
        if name == "prior":
            continue
        if name.startswith("without "):
            bf = posterior.bayes_factor(k, n, c["passed"], c["n"])
            factors.append({"what": name[len("without "):], "kind": "term", **bf, "passed": c["passed"], "n": c["n"]})
        else:
            bf = posterior.bayes_factor(c["passed"], c["n"], k, n)
            factors.append({"what": name[len("with "):], "kind": "candidate", **bf, "passed": c["passed"], "n": c["n"]})
    return {"n": n, "passed": k, "share": posterior.share(k, n), "verdicts": verdicts, "draws": draws, "ok": ok,
            "marginals": posterior.marginals(draws, ok, result["seed"]), "held_out": posterior.held_out(verdicts),
            "factors": factors, "point": posterior.nearest_median(draws, ok) if k else None}


def _pct(k: int, n: int) -> str:
    p, e = posterior.share(k, n) if n else (float("nan"), float("nan"))
    return f"{100 * p:.1f} +- {100 * e:.1f} % ({k} of {n})" if n else "- (none given)"


def _g(x: float) -> str:
    return f"{x:.4g}"


def _factor(f: dict) -> str:
    if f["bound"] == ">":
        return f"> {f['value']:.2f} (none of {f['n']} pass without it)"
    if f["bound"] == "<":
        return f"< {f['value']:.2f} (none of {f['n']} pass with it)"
    if f["factor"] is None:
        return "- (neither passes)"
    return f"{f['factor']:.2f} +- {f['error']:.2f}"


def pinned(a: dict) -> list[str]:
    """What the evidence pins down: the ranges whose posterior 90 % interval is at most 70 % of the
    prior's, each said as the side it moved to."""
    out = []
    for m in a["marginals"]:
        if m["posterior"] is None:
            continue
        (p5, _, p95), (q5, q50, q95) = m["prior"], m["posterior"]
        if q95 - q5 > 0.7 * (p95 - p5):
            continue
        if q95 < p95 - 0.15 * (p95 - p5):
            out.append(f"`{m['range']}` below {_g(q95)} (95 % of the posterior; the prior's 95 % point {_g(p95)})")
        elif q5 > p5 + 0.15 * (p95 - p5):
            out.append(f"`{m['range']}` above {_g(q5)} (95 % of the posterior; the prior's 5 % point {_g(p5)})")
        else:
            out.append(f"`{m['range']}` within {_g(q5)}-{_g(q95)} (the prior's {_g(p5)}-{_g(p95)})")
    return out


def render(result: dict) -> str:
    a = analyse(result)
    n, k = a["n"], a["passed"]
    lines = [f"`python scripts/as_flown_posterior.py --n {n} --n-off {_off_n(result)} --seed {result['seed']}` "
             f"({result['seconds']} s of wall time for every model): {n} draws of every range of {result['prior']}, "
             f"each flown on the batched simulator (the paper flight with both gain sets, and its hover before the "
             f"first bank again with Table 6 and the gyro recorded), judged by each observation "
             f"(sim/sweeps/evidence.py). **{_pct(k, n)} pass the evidence** (every informative observation; the "
             f"error is the share's Monte Carlo standard error).", "",
             "The evidence, each observation's verdict over the prior's draws:", ""]
    rows = []
    for o in evidence.OBSERVATIONS:
        kk = int(a["verdicts"][o.id].sum())
        rows.append([o.id, o.source, o.says, o.tolerance, _pct(kk, n) + ("" if o.informative else ", not informative")])
    lines += table(["observation", "source", "the paper says", "the test and its tolerance", "prior draws passing"], rows)
    lines += ["", "The marginals before (the prior: every draw) and after (the draws that pass), 5 / 50 / 95 % "
              "(the posterior's median with its bootstrap error):", ""]
    rows = []
    for m in a["marginals"]:
        p, q, e = m["prior"], m["posterior"], m["error"]
        rows.append([f"`{m['range']}`", " / ".join(_g(x) for x in p),
                     " / ".join(_g(x) for x in q) + f" (median +- {_g(e[1])})" if q else "-"])
    lines += table(["range", "prior", "posterior"], rows)
    pins = pinned(a)
    lines += ["", "What the evidence pins down (a posterior 90 % interval at most 0.7 of the prior's): "
              + ("; ".join(pins) + "." if pins else "nothing at this size.")
              + " A motor time constant pinned here is what `flightctl bench --profile step` on the real motor "
                "would check.", "",
              "Held out: condition on every informative observation but one and predict that one: the share of "
              "those draws that pass it (the posterior's prediction) against the share of all draws (the prior's):", ""]
    rows = [[h["observation"], _pct(*h["prior"]), _pct(*h["posterior"])] for h in a["held_out"]]
    lines += table(["held-out observation", "prior predicts", "posterior (given all the others) predicts"], rows)
    lines += ["", "Each term's gain as evidence: the Bayes factor of the model with the term against the model "
              "without it (a candidate: with it against the model as it is), the ratio of the shares of their "
              "priors that pass the evidence, with its Monte Carlo error (above 1: the paper's flights are more "
              "probable with it):", ""]
    rows = [[f"`{f['what']}`", f["kind"], _pct(f["passed"], f["n"]), _factor(f)] for f in a["factors"]]
    rows += [[f"`{name}`", "candidate", "not measured", why] for name, why in posterior.NOT_MEASURED]
    lines += table(["term", "kind", "passing without it (a candidate: with it)", "Bayes factor"], rows)
    if a["point"] is not None:
        d = {f"{c}.{p}": float(v[a['point']]) for (c, p), v in a["draws"].items()}
        lines += ["", f"The posterior's file, `--params paper-posterior` (flightctl/vehicles/paper-posterior.toml): "
                  f"its point is draw {a['point']} (seed {result['seed'] + a['point']}), the passing draw nearest the "
                  f"posterior's median; its ranges the posterior's 5-95 % intervals (the table above), widened to hold the "
                  f"point where it lies outside them. The point: "
                  + ", ".join(f"`{k}` {_g(v)}" for k, v in d.items()) + "."]
    return "\n".join(lines)


def _off_n(result: dict) -> int:
    sizes = [c["n"] for name, c in result["models"].items() if name != "prior"]
    return sizes[0] if sizes else 0


def facts(result: dict) -> str:
    """The README's short table, prior and posterior side by side: per observation the share of the
    prior's draws that pass it, and the share of the draws passing every other one that pass it (the
    posterior's prediction of it, held out); then the ranges the evidence pins down."""
    a = analyse(result)
    held = {h["observation"]: h for h in a["held_out"]}
    rows = []
    for o in evidence.OBSERVATIONS:
        v = a["verdicts"][o.id]
        post = _pct(*held[o.id]["posterior"]) if o.id in held else "not informative"
        rows.append([f"{o.id} ({o.source})", _pct(int(v.sum()), a["n"]), post])
    rows.append(["all of the evidence", _pct(a["passed"], a["n"]), "the posterior: the draws that pass all of it"])
    lines = table(["the paper's observation (sim/sweeps/evidence.py)", f"prior: {result['prior']}'s ranges",
                   "posterior given every other observation (held out)"], rows)
    pins = pinned(a)
    lines += ["", f"Seed {result['seed']}, `python scripts/as_flown_posterior.py` (docs/as-flown.md): what the "
              f"evidence pins down: " + ("; ".join(pins) if pins else "nothing at this size") + "."]
    return "\n".join(lines)


def write_vehicle(result: dict, path: Path = VEHICLE) -> None:
    """The posterior's parameter file: paper-as-flown with its ranges at the posterior's 5-95 % and its
    values at the passing draw nearest the posterior's median, each value's source saying so."""
    import dataclasses

    from flightctl.files import write_atomic
    from flightctl.params import EffectSpec, dumps, load
    from flightctl.sim.sweeps import montecarlo
    a = analyse(result)
    if a["point"] is None:
        raise SystemExit("as_flown_posterior.py: no draw passes the evidence: no posterior file written")
    prior = load(PRIOR)
    k = a["point"]
    point = {key: float(v[k]) for key, v in a["draws"].items()}
    spans = {tuple(m["range"].split(".", 1)): m["posterior"] for m in a["marginals"]}

    def span(cause, name, value):
        q5, _, q95 = spans[(cause, name)]
        return (min(q5, value), max(q95, value))
    p = montecarlo.drawn_params(prior, point)
    p = dataclasses.replace(
        p, ranges=tuple((nm, *span(montecarlo.AIRFRAME, nm, point[(montecarlo.AIRFRAME, nm)])) for nm, _, _ in prior.ranges),
        table_ranges=tuple((t, nm, *span(t, nm, point[(t, nm)])) for t, nm, _, _ in prior.table_ranges),
        effects=tuple(EffectSpec(e.cause, e.parameters, e.source + "; posterior: see the file's head",
                                 tuple((nm, *span(e.cause, nm, dict(e.parameters)[nm])) for nm, _, _ in e.ranges))
                      for e in p.effects))
    how = (f"the posterior's point (draw {k} of {a['n']}, seed {result['seed']}, nearest its median; "
           f"scripts/as_flown_posterior.py)")
    sources = {nm: f"{how}; prior range and derivation in paper-as-flown: {prior.source(nm)}"
               for (c, nm) in point if c in (montecarlo.AIRFRAME, *montecarlo.TABLES)}
    head = (f"# The paper's vehicle as its own flights say it was: paper-as-flown's ranges conditioned on the\n"
            f"# paper's evidence (sim/sweeps/evidence.py) by rejection ABC on the batched simulator,\n"
            f"# {a['passed']} of {a['n']} draws passing (seed {result['seed']}). Values: the passing draw nearest the\n"
            f"# posterior's median (draw {k}); ranges: the posterior's 5-95 % intervals (a box around the posterior,\n"
            f"# not the posterior itself). Written by scripts/as_flown_posterior.py; do not edit by hand.\n")
    write_atomic(path, head + dumps(p, sources, tables=("filters", "sensors")))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 epilog=__doc__.split("\n\n", 1)[1], formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=16000, help="draws of the prior (default 16000: about 120 pass)")
    ap.add_argument("--n-off", type=int, default=1500, help="draws of each other model (default 1500)")
    ap.add_argument("--seed", type=int, default=44)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--from", dest="source", help="render this run's JSON instead of flying")
    ap.add_argument("--doc", help="write docs/as-flown.md's block into this file")
    ap.add_argument("--readme", help="write the README's block into this file")
    ap.add_argument("--json", default=str(JSON), help="where a run writes its JSON")
    ap.add_argument("--vehicle", default=str(VEHICLE), help="where a run writes the posterior's parameter file")
    args = ap.parse_args(argv)
    if args.n < 1 or args.n_off < 1 or args.workers < 1:
        print("as_flown_posterior.py: --n, --n-off and --workers must be at least 1", file=sys.stderr)
        return 2
    if args.source:
        try:
            result = json.loads(Path(args.source).read_text())
        except (OSError, ValueError) as e:
            print(f"as_flown_posterior.py: {args.source}: {e}", file=sys.stderr)
            return 2
        if args.doc:
            write_or_exit(args.doc, *DOC_MARKS, render(result))
        if args.readme:
            write_or_exit(args.readme, *README_MARKS, facts(result))
        if not (args.doc or args.readme):
            print(render(result))
        return 0
    result = run(args.n, args.n_off, args.seed, args.workers)
    from flightctl.files import write_atomic
    write_atomic(args.json, json.dumps(result) + "\n")
    write_or_exit(args.doc or DOC, *DOC_MARKS, render(result))
    write_or_exit(args.readme or README, *README_MARKS, facts(result))
    a = analyse(result)
    if a["passed"]:
        write_vehicle(result, Path(args.vehicle))
    print(f"{a['passed']} of {a['n']} pass the evidence; {result['seconds']} s; -> {args.json}"
          + (f", {args.vehicle}" if a["passed"] else ", no draw passes: no parameter file"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
