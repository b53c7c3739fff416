"""Where the batched simulator's time goes, in instructions (not seconds: a count that other work on the
machine does not move): `python scripts/batch_profile.py [--vehicles N] [--seconds S] [--workers W]`.

It runs itself under valgrind's callgrind (`--inner`), counting only the instructions inside numba's
compiled calls (callgrind's inclusive count of `call_cfunc`, numba/_dispatcher.cpp: the compiled code
and its arguments' unboxing; numba's loading from its cache is outside), and beside them all of the
process's (the set-up in Python). The imports run uninstrumented; the inner process ends each section
with `callgrind_control --dump=LABEL`, so that each section's count is its own:

- `batch`: `sim.sweeps.batch.simulate` of N as-flown vehicles, each with its own draw and seed, from
  power-on through the calibration and S s of the take-off (scripts/benchmark.py's flight, smaller):
  instructions per vehicle-step of the compiled loop;
- the phases, each the compiled copy the loop inlines, called in a compiled loop over the vehicles'
  states as the batch left them (in the air): the plant's RK4 step (four evaluations), one evaluation
  of its forces (the chip's read), the chip's burst (`imu.chip_frame` with `flight.put_word`), the
  rotors' vibration lines alone (`imu.vibration`: the sines and cosines), the chip's normals
  (`flight.normals`: numba's PCG64 and ziggurat), CPython's gauss on the Mersenne Twister's uniforms,
  the controller (`onboard.step`: the estimator, the PIDs, the mixer); each per call, and per
  vehicle-step at the rate the loop calls it.

`--against REV` counts the `batch` section (and the 2 s more in the air) of the same flight again on the
code of REV, a commit of this checkout (its flightctl, sim and hil trees exported by `git archive` into
a temporary folder, imported from there, numba compiling them afresh): whether a change of the
benchmark's rate between two stops is the code's (its instructions per vehicle-step moved) or the
machine's (they did not), which timing on a shared machine cannot tell.

`--workers W` (the set-up and dispatch's own cost, item 3 of issue 48) counts the CPU-seconds of the
batch on W of the engine's worker processes against one, outside valgrind: this process's and the
workers' (`time.process_time` in each, before and after, the workers started by a first small batch).
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

from flightctl.errors import InputError

from flightctl.files import output_file, write_atomic

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

HEADER = ("| phase | instructions a call | calls a vehicle-step | instructions a vehicle-step in the air | share |",
          "|---|---|---|---|---|")
STAMP = ("Measured by `python scripts/batch_profile.py --markdown` on {date}: {machine}; instructions counted by "
         "valgrind's callgrind, inside numba's compiled calls.")
PHASES = (("rk4", "the plant's RK4 step (four evaluations: the rotors, the effects, the rigid body, 3 sines and cosines each)"),
          ("forces", "the plant's forces once more, at the chip's read"),
          ("vibration", "the rotors' vibration lines (`imu.vibration`: 8 sines and cosines of `imu.sincos`, 24 roots, 24 divisions)"),
          ("chip", "the chip's registers but the lines (`imu.chip_frame`: the DLPF, the bias walk, the broadband, the rounding)"),
          ("normals", "the chip's normals (`flight.normals`: NumPy's ziggurat on PCG64, sim/sweeps/pcg64.py, NumPy's numbers)"),
          ("gauss", "CPython's gauss on the Mersenne Twister's uniforms (the sonar's jitter, the power monitor)"),
          ("controller", "the controller (`onboard.step`: the estimator, the PIDs of eq. 24, the mixer of eq. 25)"))
CPU_NAME = "haswell"      # the code compiled for: AVX2 and scalar SSE, which valgrind runs (not AVX-512)
REPS = 20                # each phase's calls per vehicle
AIR_S = 2.0              # s more of flight: the difference is a vehicle-step in the air


UNDER = "BATCH_PROFILE_UNDER_VALGRIND"
_marked: list = []


def _mark(label: str) -> None:
    """The section up to here dumped by callgrind as `label` (the first mark turns its instrumentation on)."""
    if not os.environ.get(UNDER):
        return                         # (the run outside valgrind that compiles)
    pid = str(os.getpid())
    if not _marked:
        _marked.append(label)
        subprocess.run(["callgrind_control", "--instr=on", pid], check=True, stdout=subprocess.DEVNULL)
    subprocess.run(["callgrind_control", f"--dump={label}", pid], check=True, stdout=subprocess.DEVNULL)


def _flight(n: int, seconds: float):
    from flightctl.params import load
    from flightctl.sim.flights.scenarios import SCENARIOS
    from flightctl.sim.sweeps.montecarlo import draw
    params = load("paper-as-flown")
    return params, SCENARIOS["paper"]().plan, draw(params, n, 0)


def _phase_loops():
    """The phases' compiled loops: each calls one compiled copy the batch's loop inlines, REPS times per vehicle."""
    from flightctl.sim.sweeps import twin_world as tw
    from flightctl.sim.sweeps import twin_controller as ob
    from flightctl.sim.sweeps import pcg64
    from flightctl.sim.world import compiled, imu
    cc = compiled.compiled_copy
    plant = compiled.functions()
    o = ob.compiled_functions(cc)
    held = cc(tw.held_command)
    u = cc(tw.uniform)
    return {
        "rk4": cc(rk4_loop, allocates=True, work=plant["work"], rk4=plant["rk4"], held_command=held),
        "forces": cc(forces_loop, allocates=True, work=plant["work"], forces=plant["forces"], held_command=held),
        "chip": cc(chip_loop, allocates=True, chip_words=imu.chip_frame_compiled(tw.put_word)),
        "vibration": cc(vibration_loop, vibration=cc(imu.vibration, remainder=cc(imu.remainder), sincos=cc(imu.sincos))),
        "normals": cc(normals_loop, allocates=True, normals=cc(tw.normals, standard_normal=pcg64.compiled_normal(cc)),
                      normals_per_read=cc(imu.normals_per_read)),
        "gauss": cc(gauss_loop, gauss=cc(tw.gauss, uniform=u)),
        "controller": cc(controller_loop, allocates=True, ob_step=o["step"]),
    }


def rk4_loop(X, W, Q, codes, dt, reps):
    wk = work(X.shape[1])
    for v in range(X.shape[0]):
        for _ in range(reps):
            rk4(X[v], held_command(W[v]), codes, Q[v], dt, wk, False)
    return wk[0]


def forces_loop(X, W, Q, codes, reps):
    wk = work(X.shape[1])
    s = 0.0
    for v in range(X.shape[0]):
        for r in range(reps):
            u = (v + r) % X.shape[0]      # another state each call (no trig remembered from the last)
            f, _, force, _, rw = forces(X[u], held_command(W[u]), codes, Q[u], wk)
            s += f[0] + force[2] + rw[0]
    return s


def chip_loop(W, WORDS, CS, CC, dt, reps):
    e = np.zeros(12)
    s = 0
    for v in range(W.shape[0]):
        w = W[v]
        c = 103                        # flight.W_FW: the rotors' thrusts, then speeds
        for r in range(reps):
            chip_words(WORDS[v], CS[v], CC[v], e, 0, 0.1, 0.2, 9.8, 0.01, 0.02, 0.03, w[c], w[c + 1], w[c + 2],
                       w[c + 3], w[c + 4], w[c + 5], w[c + 6], w[c + 7], r * 1e-4, dt, 30.0, True)
            s += WORDS[v, 0]
    return s


def vibration_loop(W, CS, CC, dt, reps):
    s = 0.0
    for v in range(W.shape[0]):
        w = W[v]
        c = 103
        for r in range(reps):
            out = vibration(CS[v], CC[v], w[c], w[c + 1], w[c + 2], w[c + 3], w[c + 4], w[c + 5], w[c + 6], w[c + 7],
                            r * 1e-4, dt)
            s += out[0] + out[3]
    return s


def normals_loop(W, GEN, CC, reps):
    e = np.zeros(15)
    for v in range(W.shape[0]):
        nn = normals_per_read(CC[v])
        for _ in range(reps):
            normals(GEN[v], W[v], e, 0, nn)
    return e[0]


def gauss_loop(W, UNI, reps):
    s = 0.0
    for v in range(W.shape[0]):
        for _ in range(reps):
            s += gauss(W[v], UNI[v], 0.0, 1.0)
        W[v, 48] = 0.0                 # flight.W_U: the stream's start again (reps < its length)
    return s


def controller_loop(E, KC, W, dt, reps):
    cnt = np.zeros(4, dtype=np.int64)
    s = 31                             # flight.W_S: the sample
    for v in range(E.shape[0]):
        w = W[v]
        for _ in range(reps):
            ob_step(E[v], KC[v], w[s + 3], w[s + 4], w[s + 5], w[s], w[s + 1], w[s + 2], w[s + 6], w[s + 7], w[s + 8],
                    True, dt, 0.0, 0.0, 0.0, 1.0, cnt)
    return cnt[0]


def _inner(n: int, seconds: float, out: str, batch_only: bool = False) -> None:
    from flightctl.sim.sweeps import batch
    from flightctl.sim.sweeps import twin_loop as fl
    from flightctl.sim.sweeps import twin_world as tw
    params, plan, draws = _flight(n, seconds)
    run = fl.compiled_fly()
    kept = {}

    def recording(*args):            # the batch's loop, its arrays kept at the last chunk (this driver only)
        run(*args)
        kept["args"] = args
    batch.fl.compiled_fly = lambda: recording
    _mark("load")                      # instrumented from here (the imports ran uninstrumented, faster)
    flight = batch.simulate(params, plan, n, draws, until=seconds)
    _mark("batch")
    longer = batch.simulate(params, plan, n, draws, until=seconds + AIR_S)
    _mark("longer")
    sections = {"batch": flight.vehicle_steps, "longer": longer.vehicle_steps}
    if batch_only:                     # (--against: another commit's code, whose phases may be named otherwise)
        with open(out, "w") as f:
            json.dump({"sections": sections}, f)
        return
    from flightctl.sim.world.imu import normals_per_read
    loops = _phase_loops()
    X, W, E, KC, Q, codes, RING, NRING, FRAC, WORDS, CS, CC, GEN, UNI = kept["args"][:14]
    k = kept["args"][16]
    dt = float(k[tw.DT])
    nn = float(np.mean([normals_per_read(c) for c in CC]))
    mag = 1.0 / tw.MAG_EVERY
    rate = {"rk4": 1.0, "forces": 1.0, "chip": 1.0, "vibration": 1.0, "normals": (nn + 3 * mag) / nn,
            "gauss": 1.0 * k[tw.INA_DRAWS] / k[tw.POWER_EVERY] + 1.0 / k[tw.SONAR_EVERY], "controller": 1.0}
    calls = {
        "rk4": lambda: loops["rk4"](X, W, Q, codes, dt, REPS),
        "forces": lambda: loops["forces"](X.copy(), W, Q, codes, REPS),
        "chip": lambda: loops["chip"](W, WORDS, CS.copy(), CC, dt, REPS),
        "vibration": lambda: loops["vibration"](W, CS.copy(), CC, dt, REPS),
        "normals": lambda: loops["normals"](W.copy(), GEN, CC, REPS),
        "gauss": lambda: loops["gauss"](W.copy(), UNI, REPS),
        "controller": lambda: loops["controller"](E.copy(), KC, W, dt, REPS),
    }
    for name, call in calls.items():
        call()                         # compiled (or loaded) outside the section
        _mark("warm " + name)
        call()
        _mark(name)
        sections[name] = X.shape[0] * REPS    # (the last group's vehicles: GROUP at most)
    with open(out, "w") as f:
        json.dump({"sections": sections, "rate": rate}, f)


def _counts(folder: str) -> dict[str, tuple[int, int]]:
    """(all instructions, those inside numba's compiled calls) of each of callgrind's dumps in `folder`, by label."""
    out = {}
    for f in os.listdir(folder):
        path = os.path.join(folder, f)
        with open(path) as fh:
            text = fh.read()
        label, total = re.search(r"^desc: Trigger: (.*)$", text, re.M), re.search(r"^summary: (\d+)", text, re.M)
        if not (label and total and label.group(1).startswith("dump ")):
            continue
        text = subprocess.run(["callgrind_annotate", "--inclusive=yes", "--threshold=100", path],
                              capture_output=True, text=True).stdout
        inside = [int(line.split()[0].replace(",", "")) for line in text.splitlines() if "call_cfunc" in line]
        out[label.group(1)[5:]] = (int(total.group(1)), max(inside, default=0))
    return out


def _counted(n: int, seconds: float, extra: tuple[str, ...] = (), path: str | None = None) -> tuple[dict, dict]:
    """(the inner run's sections, callgrind's counts by label) of the flight of n vehicles, S s after
    arming; `path`: the package folder to import flightctl from (another commit's: scripts/revision.py)."""
    here = os.path.abspath(__file__)
    # numba compiles for the CPU it sees, and keys its cache by it: valgrind's (no AVX-512) is not this
    # one's, so that it would compile afresh under valgrind, for an hour. Both runs compile for CPU_NAME.
    env = {**os.environ, "NUMBA_CPU_NAME": CPU_NAME, "NUMBA_CPU_FEATURES": ""}
    if path is not None:
        env["PYTHONPATH"] = path
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "sections.json")
        # natively first: numba compiles (and caches) the phases' loops, so that valgrind only loads them
        subprocess.run([sys.executable, here, "--inner", out, "--vehicles", "2", "--seconds", "0.01", *extra],
                       check=True, env=env)
        subprocess.run(["valgrind", "--tool=callgrind", "--instr-atstart=no",
                        "--cache-sim=no", "--dump-instr=no", f"--callgrind-out-file={tmp}/cg.%p",
                        sys.executable, here, "--inner", out, "--vehicles", str(n), "--seconds", str(seconds), *extra],
                       check=True, stderr=subprocess.DEVNULL, env={**env, UNDER: "1"})
        with open(out) as f:
            meta = json.load(f)
        return meta, _counts(tmp)


def against(rev: str, n: int, seconds: float) -> dict:
    """The batch's instructions per vehicle-step on commit `rev`'s code (scripts/revision.py), as `profile` counts them."""
    import revision
    with tempfile.TemporaryDirectory() as tmp:
        meta, by = _counted(n, seconds, ("--batch-only",), revision.package(rev, tmp))
    steps, more = meta["sections"]["batch"], meta["sections"]["longer"]
    return {"rev": rev, "per_step": by["batch"][1] / steps, "whole_per_step": by["batch"][0] / steps,
            "per_air_step": (by["longer"][1] - by["batch"][1]) / (more - steps)}


def profile(n: int, seconds: float) -> dict:
    meta, by = _counted(n, seconds)
    steps, more = meta["sections"]["batch"], meta["sections"]["longer"]
    phases = {name: (by[name][1] / meta["sections"][name], meta["rate"][name]) for name in meta["rate"]}
    return {"vehicles": n, "seconds": seconds, "vehicle_steps": steps, "per_step": by["batch"][1] / steps,
            "whole_per_step": by["batch"][0] / steps, "air_steps": more - steps,
            "per_air_step": (by["longer"][1] - by["batch"][1]) / (more - steps), "phases": phases}


def table(r: dict) -> list[str]:
    """The profile as docs/batch.md's table: each phase per call and per vehicle-step in the air, the rest of
    the loop (the difference), the whole in the air and over the benchmark's flight."""
    ph = r["phases"]
    per = {name: ph[name][0] * ph[name][1] for name in ph}
    per["chip"] -= per["vibration"]              # `chip` calls `vibration`: its own part only
    calls = {name: ph[name][1] for name in ph}
    air = r["per_air_step"]
    rows = [f"| {label} | {(ph[name][0] if name != 'chip' else ph[name][0] - ph['vibration'][0]):,.0f} | "
            f"{calls[name]:.3g} | {per[name]:,.0f} | {per[name] / air:.0%} |" for name, label in PHASES]
    rest = air - sum(per.values())
    rows.append(f"| the rest of the loop: the delay ring, the floor's test, the driver's decode and checks, the sonar's "
                f"edges, the loop's rules, the record | - | 1 | {rest:,.0f} | {rest / air:.0%} |")
    rows.append(f"| a vehicle-step in the air ({r['air_steps']:,} of {r['vehicles']} vehicles' steps) | - | 1 | "
                f"{air:,.0f} | 100% |")
    rows.append(f"| a vehicle-step of the benchmark's flight (the calibration's 2 s on the floor, {r['seconds']:g} s of "
                f"take-off; the set-up in Python besides: {r['whole_per_step']:,.0f} in all) | - | 1 | "
                f"{r['per_step']:,.0f} | - |")
    setup = r["whole_per_step"] - r["per_step"]
    rows.append(f"| the set-up in Python, spread over the benchmark flight's vehicle-steps (each vehicle's Mersenne "
                f"Twister seeded and its chip's die drawn, the groups' arrays, the judging) | - | 1 | {setup:,.0f} | "
                f"{setup / r['whole_per_step']:.0%} of the flight's all |")
    if "against" in r:
        rows += against_rows(r)
    return [*HEADER, *rows]


def against_rows(r: dict) -> list[str]:
    """The rows of `--against`: the batch's counts on that commit's code, and this code's change from them."""
    import revision
    o = r["against"]
    day = revision.day(o["rev"])
    change = lambda now, then: f"this code {100.0 * (now / then - 1.0):+.1f} %"
    return [f"| a vehicle-step in the air on the code of {o['rev']} ({day}; `--against {o['rev']}`) | - | 1 | "
            f"{o['per_air_step']:,.0f} | {change(r['per_air_step'], o['per_air_step'])} |",
            f"| a vehicle-step of the benchmark's flight on the code of {o['rev']} (the set-up in Python besides: "
            f"{o['whole_per_step']:,.0f} in all, {change(r['whole_per_step'], o['whole_per_step'])}) | - | 1 | "
            f"{o['per_step']:,.0f} | {change(r['per_step'], o['per_step'])} |"]


def _worker_cpu() -> float:
    return time.process_time()


def cpu_seconds(n: int, seconds: float, workers: int) -> tuple[float, float, int, float]:
    """(CPU-seconds of this process, of the engine's workers, vehicle-steps, wall s) of one batch on `workers`,
    after a first batch that starts the workers (sim/engine.py keeps them for the command's life); they
    are ended after it, so that an idle cluster takes nothing from a one-worker batch measured next."""
    from flightctl.sim import engine
    from flightctl.sim.sweeps import batch
    from flightctl.sim.sweeps import twin_loop as fl
    params, plan, draws = _flight(n, seconds)
    fl.compiled_fly()
    batch.simulate(params, plan, 2 * workers, {k: v[:2 * workers] for k, v in draws.items()}, until=0.01,
                   workers=workers)
    client = engine._engine.get("client")

    def workers_cpu() -> float:
        return sum(client.run(_worker_cpu).values()) if client is not None else 0.0
    before, here, wall = workers_cpu(), time.process_time(), time.perf_counter()
    flight = batch.simulate(params, plan, n, draws, until=seconds, workers=workers)
    wall = time.perf_counter() - wall
    here, used = time.process_time() - here, workers_cpu() - before
    engine.close()
    return here, used, flight.vehicle_steps, wall


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--vehicles", type=int, default=200)
    ap.add_argument("--seconds", type=float, default=1.0, help="s after arming (the calibration's 2 s before)")
    ap.add_argument("--workers", type=int, default=0, help="CPU-seconds on this many workers against one")
    ap.add_argument("--repeat", type=int, default=3, help="--workers: runs of each (the best kept)")
    ap.add_argument("--json", help="the figures as JSON")
    ap.add_argument("--markdown", action="store_true", help="print docs/batch.md's block: the date, the machine, a table")
    ap.add_argument("--against", metavar="REV", help="the batch's instructions per vehicle-step on this commit's code too")
    ap.add_argument("--inner", help=argparse.SUPPRESS)
    ap.add_argument("--batch-only", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.vehicles < 1 or not 0.0 < a.seconds <= 60.0 or a.workers < 0 or a.repeat < 1:
        print("batch_profile: --vehicles at least 1, --seconds in (0, 60], --workers 0 or more, --repeat at least 1",
              file=sys.stderr)
        return 2
    if not (a.inner or a.workers) and not (shutil.which("valgrind") and shutil.which("callgrind_control")):
        print("batch_profile: valgrind (its callgrind and callgrind_control) is not installed", file=sys.stderr)
        return 2
    if a.inner:
        _inner(a.vehicles, a.seconds, a.inner, a.batch_only)
        return 0
    if a.workers:
        best = {}
        for k in range(a.repeat):
            for w in sorted({1, a.workers}):
                here, used, steps, wall = cpu_seconds(a.vehicles, a.seconds, w)
                total = here + used
                best[w] = min(best.get(w, (np.inf,) * 3), (total, wall, here))
                print(f"{w} worker(s): {total:.2f} CPU-s ({here:.2f} in this process, {used:.2f} in the workers) for "
                      f"{steps} vehicle-steps, {steps / total / 1e6:.3f} M per CPU-s, {wall:.2f} s of wall time",
                      flush=True)
        if a.workers > 1:
            one, many = best[1], best[a.workers]
            print(f"best of {a.repeat}: {a.workers} workers take {many[0] / one[0]:.3f} of one's CPU-seconds (this "
                  f"process {many[2]:.2f} s of them): {a.workers * one[0] / many[0]:.2f}x one on {a.workers} free "
                  f"cores; {one[1] / many[1]:.2f}x one in wall time, on this machine as loaded")
        return 0
    try:
        out = output_file(a.json, "--json") if a.json else None
    except InputError as e:
        print(f"batch_profile: {e}", file=sys.stderr)
        return 2
    if a.against is not None:
        import revision
        with tempfile.TemporaryDirectory() as tmp:
            try:
                revision.package(a.against, tmp)   # a commit git does not know: refused before any count
            except InputError as e:
                print(f"batch_profile: {e}", file=sys.stderr)
                return 2
    r = profile(a.vehicles, a.seconds)
    if a.against is not None:
        r["against"] = against(a.against, a.vehicles, a.seconds)
    if out is not None:
        write_atomic(out, json.dumps(r, indent=1))
    lines = table(r)
    if a.markdown:
        from benchmark import machine
        lines = [STAMP.format(date=datetime.date.today().isoformat(), machine=machine()), ""] + lines
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
