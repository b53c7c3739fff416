"""Every generated block and figure of the README and docs/, and the command that writes it.

    python scripts/docs.py --list                       the blocks and figures, their commands
    python scripts/docs.py --write [ID ...] [--quick]   run the commands and rewrite them (all by default;
                                                        --quick leaves out the long ones)
    python scripts/docs.py --check [ID ...] [--quick]   run the commands into a temporary folder and say
                                                        which differ from what the files hold (exit 1)

A number in the README or docs/ is a claim, written by the command that measures it between two
markers (`<!-- NAME: begin -->` ... `<!-- NAME: end -->`, invisible on GitHub; flightctl/sim/docs.py
reads and replaces them), never by hand. A block is one of:
- printed: the command's standard output is the block (in a code fence where `fence`);
- written: the command rewrites the block in the file itself (`{doc}`: the file, `{dir}`: its folder);
  checked on a copy of the file in a temporary folder;
- measured on a machine: the speed figures of scripts/benchmark.py, the batch's instruction counts of
  scripts/batch_profile.py (numba's code and valgrind's version), diagnose's CPU against an earlier
  commit's of scripts/diagnose_speed.py and the HIL link's latency of
  scripts/hil_latency.py vary with the machine and its load; the block says when and where they were
  measured, and the check holds only its form (the stamp line, the table's header and rows), never
  its numbers.
A figure is a PNG its command draws; checked against a fresh drawing (the same size, at most 1 % of
its pixels different: the fonts of another machine's matplotlib move a few).
tests/project/test_docs.py re-runs every block and figure (the long ones under `-m slow`) and fails when
one differs. Prose around a block states no number of its own (docs/analyze.md, docs/diagnose.md).
"""
from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

from flightctl.sim.docs import marked

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))

FLIGHTCTL = ("{python}", "-P", "-m", "flightctl.cli")
SCRIPT = ("{python}",)


@dataclass(frozen=True)
class Block:
    id: str
    file: str                     # relative to the checkout
    begin: str
    end: str
    command: tuple[str, ...]      # {python}, {doc}, {dir}, {tmp} are filled in
    minutes: float = 0.1          # about, on a 2-core machine: over 1 is long (--quick leaves it out)
    fence: bool = False           # printed into a ``` code fence
    measured: bool = False        # machine-dependent figures: the form is checked, not the numbers
    verdict: bool = False         # exit status 1 is the command's verdict (a fault not detected), not a failure

    @property
    def written(self) -> bool:
        return any("{doc}" in a or "{dir}" in a for a in self.command)


@dataclass(frozen=True)
class Figure:
    id: str
    files: tuple[str, ...]        # the PNGs the command draws, relative to the checkout
    command: tuple[str, ...]      # {out} is the first file's path, {tmp} a scratch folder
    minutes: float = 0.1


def analyze(id_: str, name: str, *args: str) -> Block:
    return Block(id_, "docs/analyze.md", *marked(name), FLIGHTCTL + ("analyze", *args), fence=True)


BLOCKS = (
    Block("paper-table", "README.md", *marked("paper_comparison"), SCRIPT + ("scripts/paper_comparison.py",),
          minutes=6),
    Block("benchmark", "README.md", *marked("benchmark"), SCRIPT + ("scripts/benchmark.py", "--markdown"),
          minutes=11, measured=True),
    Block("batch-profile", "docs/batch.md", *marked("batch profile"),
          SCRIPT + ("scripts/batch_profile.py", "--against", "c36445f", "--markdown"), minutes=15, measured=True),
    Block("hil-latency", "docs/hil.md", *marked("hil latency"), SCRIPT + ("scripts/hil_latency.py", "--markdown"),
          minutes=4, measured=True),
    Block("fault-matrix", "docs/safety.md", "<!-- fault matrix: begin (written by `flightctl sim faults`) -->",
          "<!-- fault matrix: end -->", FLIGHTCTL + ("sim", "faults", "--json", "{tmp}/faults.json", "--doc", "{doc}"),
          minutes=3, verdict=True),
    Block("real-flights", "docs/real-flights.md", "<!-- diagnose --corpus table: begin -->",
          "<!-- diagnose --corpus table: end -->",
          FLIGHTCTL + ("diagnose", "--corpus", "../shared/data/real/flights", "tests/data", "--table", "{doc}", "--quiet"),
          minutes=8),
    Block("late-loops", "docs/safety.md", "<!-- late loops: begin (written by `python scripts/loop_lateness.py flights`) -->",
          "<!-- late loops: end -->",
          SCRIPT + ("scripts/loop_lateness.py", "flights", "--from", "docs/late-loops.json", "--doc", "{doc}")),
    Block("motor-loss", "docs/safety.md", "<!-- motor loss: begin (written by scripts/motor_loss.py) -->",
          "<!-- motor loss: end -->", SCRIPT + ("scripts/motor_loss.py", "--doc", "{doc}", "--out", "{tmp}/m.png"),
          minutes=5),
    Block("as-flown-monte-carlo", "docs/as-flown.md", "<!-- as-flown monte carlo begin -->",
          "<!-- as-flown monte carlo end -->",
          SCRIPT + ("scripts/as_flown_mc.py", "--from", "docs/as-flown-mc.json", "--doc", "{doc}")),
    # the posterior (issue 44), rendered from its run's JSON; the run itself (2000 + 7 x 500 draws on the
    # batched simulator) is `python scripts/as_flown_posterior.py --workers 2`, about 15 min on two cores
    Block("as-flown-posterior", "docs/as-flown.md", *marked("as-flown posterior"),
          SCRIPT + ("scripts/as_flown_posterior.py", "--from", "docs/as-flown-posterior.json", "--doc", "{doc}")),
    Block("paper-facts-posterior", "README.md", *marked("paper facts posterior"),
          SCRIPT + ("scripts/as_flown_posterior.py", "--from", "docs/as-flown-posterior.json", "--readme", "{doc}")),
    Block("as-flown-gains", "docs/as-flown.md", *marked("as-flown gains"),
          SCRIPT + ("scripts/as_flown_gains.py", "--doc", "{doc}"), minutes=0.5),
    Block("estimator-bias", "docs/as-flown.md", *marked("estimator bias"),
          SCRIPT + ("scripts/estimator_bias.py", "--seeds", "4", "--doc", "{doc}"), minutes=3),
    Block("paper-facts", "README.md", "<!-- paper facts begin -->", "<!-- paper facts end -->",
          SCRIPT + ("scripts/as_flown_mc.py", "--from", "docs/as-flown-mc.json", "--readme", "{doc}")),
    Block("real-data", "docs/identification.md", "<!-- real-data:begin -->", "<!-- real-data:end -->",
          FLIGHTCTL + ("identify", "real-data", "--out", "{dir}"), minutes=1),
    Block("diagnose-pairs", "docs/diagnose.md", *marked("diagnose_pairs"),
          SCRIPT + ("scripts/diagnose_pairs.py", "--pairs", "30", "--doc", "{doc}"), minutes=2),
    Block("diagnose-sweep", "docs/diagnose.md", *marked("diagnose_sweep"),
          SCRIPT + ("scripts/diagnose_sweep.py", "--doc", "{doc}"), minutes=6),
    Block("fleet-scale", "docs/fleet.md", "<!-- fleet-scale:begin -->", "<!-- fleet-scale:end -->",
          SCRIPT + ("scripts/fleet_scale.py", "--doc", "{doc}"), minutes=8, measured=True),
    Block("fleet-detection", "docs/fleet.md", *marked("fleet-detection"),
          SCRIPT + ("scripts/fleet_detection.py", "--doc", "{doc}"), minutes=6),
    Block("diagnose-speed", "docs/diagnose.md", *marked("diagnose speed"),
          SCRIPT + ("scripts/diagnose_speed.py", "--against", "ed54a24", "--markdown"), minutes=5, measured=True),
    Block("static-tier", "docs/diagnose.md", *marked("static tier"), SCRIPT + ("scripts/static_tier.py", "--doc", "{doc}"),
          minutes=1.5),
    Block("tune-table", "docs/tune.md", *marked("tune procedure"), FLIGHTCTL + ("tune", "--out", "{tmp}/t.toml", "--doc", "{doc}"),
          minutes=1),      # 1.5 min beside other work on 2 cores (issue 39)
    Block("tune-strict", "docs/tune.md", *marked("tune strict"),
          FLIGHTCTL + ("tune", "--strict", "--out", "{tmp}/t.toml", "--doc", "{doc}"), minutes=1),
    Block("tune-robust-table", "docs/tune.md", *marked("tune robust"),
          FLIGHTCTL + ("tune", "--params", "paper-as-flown", "--robust", "40", "--seed", "1", "--out", "{tmp}/r.toml",
                       "--doc", "{doc}"), minutes=4),
    Block("open-question-table", "docs/diagnose.md", *marked("open question"),
          SCRIPT + ("scripts/open_question.py", "--from", "docs/open-question.json", "--table")),
    Block("open-question-as-flown-table", "docs/diagnose.md", *marked("open question as-flown"),
          SCRIPT + ("scripts/open_question.py", "--from", "docs/open-question-as-flown.json", "--table")),
    Block("steps-table", "docs/steps.md", *marked("steps table"), SCRIPT + ("scripts/steps_table.py",), minutes=1),
    Block("tune-from-log", "docs/tune.md", *marked("tune from log"), SCRIPT + ("scripts/fromlog_cs110.py",),
          minutes=1.5),
    Block("retune-study", "docs/tune.md", *marked("retune study"),
          SCRIPT + ("scripts/retune_study.py", "--from", "docs/retune-study.json")),
    Block("retune-study-readme", "README.md", *marked("retune study"),
          SCRIPT + ("scripts/retune_study.py", "--from", "docs/retune-study.json", "--readme")),
    Block("retune-study-posterior", "docs/tune.md", *marked("retune study posterior"),
          SCRIPT + ("scripts/retune_study.py", "--from", "docs/retune-study-posterior.json")),
    Block("retune-study-posterior-readme", "README.md", *marked("retune study posterior"),
          SCRIPT + ("scripts/retune_study.py", "--from", "docs/retune-study-posterior.json", "--readme")),
    Block("steps-predicted", "docs/steps.md", *marked("steps predicted"), SCRIPT + ("scripts/steps_predicted.py",),
          minutes=2.5),
    analyze("analyze-base-table4", "analyze base table4", "--gains", "table4", "--estimator", "truth",
            "--estimator", "flight", "--estimator", "paper"),
    analyze("analyze-base-table6", "analyze base table6", "--gains", "table6", "--estimator", "truth",
            "--estimator", "flight", "--estimator", "paper"),
    analyze("analyze-80ms", "analyze 80 ms lag", "--params", "paper-as-flown", "--gains", "table4",
            "--effect", "motor_dynamics:tau=0.08", "--estimator", "truth"),
    analyze("analyze-as-flown", "analyze as-flown table6", "--params", "paper-as-flown", "--gains", "table6",
            "--estimator", "truth", "--estimator", "flight"),
)

# One paper flight (86 s flown) and its figure: about 0.1 min compiled with numba's cache warm on an idle
# core, but 0.5 to 1 min where numba compiles afresh (a fresh install, a changed plant) and 2.5 min as
# plain Python on a busy 2-core machine (issue 39): over a minute, so that --quick leaves them out.
PAPER_FLIGHT_MIN = 1.5

FIGURES = (
    Figure("paper-base", ("docs/paper-base.png",),
           FLIGHTCTL + ("sim", "paper", "--log", "{tmp}/f.csv", "--plot", "{out}", "--quiet"), minutes=PAPER_FLIGHT_MIN),
    Figure("paper-as-flown", ("docs/paper-as-flown.png",),
           FLIGHTCTL + ("sim", "paper", "--params", "paper-as-flown", "--log", "{tmp}/f.csv", "--plot", "{out}",
                        "--quiet"), minutes=PAPER_FLIGHT_MIN),
    # the same flights as the motor-loss block (motor_loss.measure), then the figure
    Figure("motor-loss-figure", ("docs/motor-loss.png",), SCRIPT + ("scripts/motor_loss.py", "--out", "{out}"),
           minutes=5),
    Figure("steps", ("docs/steps.png",), SCRIPT + ("scripts/steps_table.py", "--out", "{out}"), minutes=1),
    Figure("tune", ("docs/tune.png",), FLIGHTCTL + ("tune", "--out", "{tmp}/t.toml", "--plot", "{out}"), minutes=1),
    Figure("tune-robust", ("docs/tune-robust.png", "docs/tune-robust-grid.png"),
           FLIGHTCTL + ("tune", "--params", "paper-as-flown", "--robust", "40", "--seed", "1", "--out",
                        "{tmp}/r.toml", "--plot", "{out}"), minutes=8),
    Figure("open-question", ("docs/open-question.png",),
           SCRIPT + ("scripts/open_question.py", "--out", "{out}"), minutes=15),
    Figure("open-question-as-flown", ("docs/open-question-as-flown.png",),
           SCRIPT + ("scripts/open_question.py", "--params", "paper-as-flown", "--out", "{out}", "--seeds", "1"),
           minutes=10),
)


def _args(command, **fill) -> list[str]:
    return [a.format(python=sys.executable, **fill) for a in command]


def run(command, verdict: bool = False, **fill) -> str:
    """Run a command in the checkout; its standard output (its progress goes to the terminal). Any exit
    status but 0 is a failure, except 1 for a command whose 1 is its verdict (`Block.verdict`)."""
    r = subprocess.run(_args(command, **fill), cwd=ROOT, stdout=subprocess.PIPE, text=True)
    if r.returncode not in ((0, 1) if verdict else (0,)):
        raise RuntimeError(f"{' '.join(command)}: exit status {r.returncode}")
    return r.stdout


def generate(b: Block, doc: Path, tmp: Path) -> str:
    """The block's text as its command writes it now, into `doc` (a copy of the file, or the file)."""
    from flightctl.sim.docs import block
    if b.written:
        run(b.command, b.verdict, doc=str(doc), dir=str(doc.parent), tmp=str(tmp))
        text = block(doc.read_text(), b.begin, b.end)
        if text is None:
            raise RuntimeError(f"{b.id}: {doc} lost its markers")
        return text
    out = run(b.command, b.verdict, tmp=str(tmp)).rstrip("\n")
    return f"```\n{out}\n```" if b.fence else out


def current(b: Block) -> str:
    from flightctl.sim.docs import block
    text = block((ROOT / b.file).read_text(), b.begin, b.end)
    if text is None:
        raise RuntimeError(f"{b.file}: no block {b.begin} ... {b.end} (once each, in that order)")
    return text


def fresh(b: Block) -> str:
    """What the block's command writes now, without touching the checkout."""
    with tempfile.TemporaryDirectory(prefix="flightctl-docs-") as tmp:
        doc = Path(tmp) / Path(b.file).name
        shutil.copyfile(ROOT / b.file, doc)
        return generate(b, doc, Path(tmp))


def write(b: Block) -> None:
    from flightctl.sim.docs import write_block
    with tempfile.TemporaryDirectory(prefix="flightctl-docs-") as tmp:
        if b.written:
            generate(b, ROOT / b.file, Path(tmp))
        elif not write_block(ROOT / b.file, b.begin, b.end, generate(b, ROOT / b.file, Path(tmp))):
            raise RuntimeError(f"{b.file}: no block {b.begin} ... {b.end}")


def draw(f: Figure, folder: Path) -> list[Path]:
    """Draw the figure's PNGs into `folder`; their paths, in the order of `f.files`."""
    folder.mkdir(parents=True, exist_ok=True)
    first = folder / Path(f.files[0]).name
    with tempfile.TemporaryDirectory(prefix="flightctl-docs-") as tmp:
        run(f.command, out=str(first), tmp=tmp)
    return [folder / Path(name).name for name in f.files]


def same_picture(a: Path, b: Path, share: float = 0.01) -> bool:
    """The same size, and at most `share` of the pixels different."""
    import numpy as np
    from PIL import Image
    x, y = (np.asarray(Image.open(p).convert("RGB"), dtype=np.int16) for p in (a, b))
    return x.shape == y.shape and float(np.mean(np.any(np.abs(x - y) > 8, axis=2))) <= share


def measured_form(b: Block, text: str) -> list[str]:
    """What is wrong with the form of a measured block (empty: it is its script's output). The script
    (the block's command's scripts/NAME.py) defines its STAMP line and its table's HEADER."""
    import importlib
    import re

    script = importlib.import_module(Path(b.command[1]).stem)
    lines = text.strip("\n").splitlines()
    problems = []
    stamp = re.escape(script.STAMP).replace(r"\{date\}", r"\d{4}-\d\d-\d\d").replace(r"\{machine\}", r".+")
    if not lines or not re.fullmatch(stamp, lines[0]):
        problems.append(f"the first line is not the stamp of {b.command[1]}: {lines[:1]}")
    if tuple(lines[2:4]) != script.HEADER:
        problems.append(f"no table header of {b.command[1]}")
    rows = lines[4:]
    cell = r" [^|]+ \|"
    columns = script.HEADER[0].count("|") - 1
    if not rows or not all(re.fullmatch(r"\|" + cell * columns, r) for r in rows):
        problems.append(f"rows that are not the {columns} columns of {script.HEADER[0]}")
    return problems


def pick(ids, quick: bool):
    items = {x.id: x for x in BLOCKS + FIGURES}
    unknown = [i for i in ids if i not in items]
    if unknown:
        raise SystemExit(f"docs.py: unknown {', '.join(unknown)} (known: {', '.join(items)})")
    chosen = [items[i] for i in ids] if ids else list(items.values())
    return [x for x in chosen if not (quick and x.minutes > 1)]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 epilog=__doc__.split("\n\n", 1)[1], formatter_class=argparse.RawDescriptionHelpFormatter)
    what = ap.add_mutually_exclusive_group(required=True)
    what.add_argument("--list", action="store_true", help="the blocks and figures, and their commands")
    what.add_argument("--write", action="store_true", help="rewrite them in the checkout")
    what.add_argument("--check", action="store_true", help="say which differ from their commands' output now")
    ap.add_argument("ids", nargs="*", metavar="ID", help="only these (default: every one)")
    ap.add_argument("--quick", action="store_true", help="leave out the ones that take over a minute")
    args = ap.parse_args(argv)
    chosen = pick(args.ids, args.quick)
    if args.list:
        for x in chosen:
            where = x.file if isinstance(x, Block) else ", ".join(x.files)
            print(f"{x.id:<30} {where:<26} ~{x.minutes:g} min  {' '.join(x.command).replace('{python}', 'python')}")
        return 0
    from flightctl.sim.progress import Progress
    bar = Progress(len(chosen), "docs ")
    differ = []
    for x in chosen:
        if isinstance(x, Block):
            if args.write:
                write(x)
            elif x.measured:
                differ += [f"{x.id}: {p}" for p in measured_form(x, current(x))]
            elif fresh(x) != current(x):
                differ.append(f"{x.id}: {x.file} differs from what `{' '.join(x.command)}` writes now")
        elif args.write:
            folder = ROOT / Path(x.files[0]).parent
            draw(x, folder)
        else:
            with tempfile.TemporaryDirectory(prefix="flightctl-docs-") as tmp:
                for new, old in zip(draw(x, Path(tmp)), x.files):
                    if not same_picture(new, ROOT / old):
                        differ.append(f"{x.id}: {old} differs from what its command draws now")
        bar.step(x.id)
    for line in differ:
        print(line)
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
