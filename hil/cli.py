"""`flightctl hil`: hardware-in-the-loop (docs/hil.md).

    flightctl hil serve --link serial:/dev/ttyUSB0,921600|tcp:PORT [--mode lockstep|free] [--json F]
    flightctl hil demo --seconds S [--link pty|tcp] [--mode lockstep|free] [--json F]

`serve` is the PC side: the simulated plant and sensors answering the flight side, which runs
`flightctl run --board hil --link ...` on the Pi. `demo` runs both ends on one machine: `serve` in a
child process, the flight side here on the "hil" board (the real loop on the wall clock), over a
pseudo-terminal pair (the flight side through pyserial) or loopback TCP, flying the hover plan.
Latency, jitter and loss are printed at the end; `--json` holds frames_sent, frames_lost,
latency_p50_ms, latency_p99_ms and outcome, the PC side's part of the latency (pc_turnaround_*), each
end's CPU time per tick and the machine's CPU over the flight (busy, stolen by a virtual machine's host).

`demo` exits 0 when the vehicle flew and landed upright, 1 when it did not (not armed, crashed, the
link lost), 3 when the hil board could not be opened, 130 on Ctrl-C (the loop stops the motors and
says goodbye to the PC side first). The motor-loss gain schedule (flightctl/control/spin.py) is
computed before the link opens, never between a live link and its first frame.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import socket
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

from flightctl.cli import EXIT_INTERRUPTED, ctrl_c_sets
from flightctl.comms import link as lk
from flightctl.boards import BoardOptions, BoardUnavailable, open_board
from flightctl.control.spin import SpinController
from flightctl.errors import InputError, Parser, seed
from flightctl.files import output_file, write_atomic
from flightctl.hal import ArmingRefused
from flightctl.loop import FlightLoop
from flightctl.params import load
from flightctl.plans.plan import Move, Plan
from flightctl.plans import TAKEOFF
from flightctl.safety import LEFT_GROUND_ALT
from flightctl.service.run import CALIBRATE_RANGE_S, prearm
from flightctl.hil.serve import Cut, HilPlant, serve

MODES = ("lockstep", "free")
SUBCOMMANDS = ("serve", "demo")         # an error names `flightctl hil demo` (flightctl/cli.py)
READY = "hil serve: ready"              # on stdout once the PC side answers (tcp: "listening on port N")
LAND_S = 4.0            # the demo's descent ramp
MAX_DEMO_S = 3600.0     # s: an hour of flight, --seconds and --cut (a pack lasts a quarter of it)


def _parser() -> argparse.ArgumentParser:
    p = Parser(prog="flightctl hil", description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="what", required=True, metavar="|".join(SUBCOMMANDS))
    s = sub.add_parser("serve", help="the PC side: the simulated plant answering the flight side")
    s.add_argument("--link", required=True, help="serial:/dev/ttyUSB0,921600 or tcp:PORT (tcp:0: any free port)")
    s.add_argument("--mode", choices=MODES, default="lockstep",
                   help="lockstep (default): the plant steps one period per command; "
                        "free: on the PC's wall clock")
    s.add_argument("--params", help="parameter file (TOML) of the simulated vehicle")
    s.add_argument("--seed", type=seed, default=0, help="seed of the sensor noise (a whole number from 0)")
    s.add_argument("--seconds", type=float, help="end after this much simulated time")
    s.add_argument("--json", help="write the PC side's figures here")
    s.add_argument("--cut", nargs=2, type=float, metavar=("AT", "FOR"),
                   help="pull the cable AT s after the first command, for FOR s (tests the failsafe)")
    d = sub.add_parser("demo", help="both ends on this machine, flying the hover plan")
    d.add_argument("--seconds", type=float, default=20.0, help="flight time after arming (default 20)")
    d.add_argument("--link", choices=("pty", "tcp"), default="pty",
                   help="pty: a pseudo-terminal as the serial cable (default); tcp: a loopback socket")
    d.add_argument("--mode", choices=MODES, default="lockstep", help="as serve --mode")
    d.add_argument("--calibrate", type=float, default=1.0, help="seconds sitting still before arming")
    d.add_argument("--params", help="parameter file (TOML)")
    d.add_argument("--seed", type=seed, default=0, help="seed of the sensor noise (a whole number from 0)")
    d.add_argument("--json", help="write the figures here")
    d.add_argument("--cut", nargs=2, type=float, metavar=("AT", "FOR"), help="as serve --cut")
    return p


def _listen(host: str, port: int) -> socket.socket:
    srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        srv.bind((host, port))
    except OSError as e:
        raise InputError(f"--link tcp:{port}: cannot listen ({e.strerror})") from None
    srv.listen(1)
    return srv


def serve_main(args) -> int:
    check_times(args)
    try:
        kind, where, n = lk.parse_link(args.link)
    except ValueError as e:
        raise InputError(str(e)) from None
    if args.json:
        output_file(args.json, "--json", ".json")
    params = load(args.params)
    # the link's end first (a port in use, a missing device: one line before the plant is built and compiled)
    if kind == "tcp":
        srv = _listen(where if args.link.count(":") == 2 else "0.0.0.0", n)   # tcp:PORT: every interface
    elif kind == "fd":
        port = lk.FdPort(n)
    else:
        try:
            port = lk.SerialPort(where, n)
        except lk.LinkError as e:
            raise InputError(str(e)) from None
    plant = HilPlant(params, args.seed)
    if kind == "tcp":       # a flight side that connects before this line waits in the listen queue
        print(f"hil serve: listening on port {srv.getsockname()[1]}", flush=True)
        conn, peer = srv.accept()
        srv.close()
        port = lk.SocketPort(conn)
    if kind != "tcp":   # imported, plant built (compiled), port open: what `hil demo` waits for before its first contact
        print(READY, flush=True)
    cut = Cut(*args.cut) if args.cut else None
    try:
        res = serve(port, plant, args.mode, args.seconds, cut)
    finally:
        port.close()
    figures = res.as_dict()
    print(f"hil serve: {res.reason}; {res.commands} commands, {res.frames_sent} frames sent, "
          f"{res.rx['frames']} received, {res.rx['lost']} lost, {res.rx['bad_crc'] + res.rx['bad_length']} corrupt, "
          f"{res.rx['out_of_order']} out of order; {res.sim_s:.2f} s simulated, max altitude {res.max_alt:.2f} m",
          file=sys.stderr)
    if args.json:
        write_atomic(args.json, json.dumps(figures, indent=2) + "\n")
    return 0


def demo_plan(seconds: float) -> Plan:
    """The hover plan for `seconds`: take off, hold, and (given the time) come down and land."""
    moves = [TAKEOFF]
    if seconds >= TAKEOFF.ramp + 2 * LAND_S:
        moves.append(Move(seconds - LAND_S - 2.0, "alt", 0.0, LAND_S))
    return Plan(moves, seconds, "hover", f"take off to {TAKEOFF.value:g} m for {seconds:g} s")


def _spawn_serve(args, tmp: Path):
    """The PC side in a child process; returns (process, the flight side's --link, fds to close), once
    the child says it is ready (imported, its plant built, its end of the link open): however long that
    takes on a busy machine, the flight side's first contact (flightctl/boards/hil.py, FIRST_CONTACT_S)
    starts only then. A child that ends before it is ready is a BoardUnavailable naming its exit code.
    `-P`: the child imports the installed flightctl, never a source tree in the current directory."""
    cmd = [sys.executable, "-P", "-m", "flightctl.cli", "hil", "serve", "--mode", args.mode, "--seed", str(args.seed),
           "--json", str(tmp / "serve.json")]
    if args.params:
        cmd += ["--params", args.params]
    if args.cut:
        cmd += ["--cut", *map(str, args.cut)]
    # its own session: Ctrl-C reaches the flight side alone, which stops and says goodbye over the link
    popen = dict(stdout=subprocess.PIPE, stdin=subprocess.DEVNULL, text=True, start_new_session=True)
    if args.link == "pty":
        master, slave = os.openpty()
        proc = subprocess.Popen(cmd + ["--link", f"fd:{master}"], pass_fds=(master,), **popen)
        os.close(master)
        _await(proc, READY, [slave])
        return proc, f"serial:{os.ttyname(slave)},{lk.DEFAULT_BAUD}", [slave]
    proc = subprocess.Popen(cmd + ["--link", "tcp:127.0.0.1:0"], **popen)
    line = _await(proc, "hil serve: listening on port ", [])
    return proc, f"tcp:127.0.0.1:{int(line.rsplit(' ', 1)[1])}", []


def _await(proc: subprocess.Popen, prefix: str, fds: list[int]) -> str:
    """The child's first line of output, which starts with `prefix`: read until it comes or the child's
    output ends (the child died), never against a clock."""
    line = proc.stdout.readline()
    if line.startswith(prefix):
        return line.strip()
    proc.kill()
    rc = proc.wait()
    for fd in fds:
        os.close(fd)
    raise BoardUnavailable(f"the PC side (flightctl hil serve) ended before it was ready (exit {rc}"
                           + (f"; it said: {line.strip()}" if line.strip() else "") + ")")


def _machine() -> tuple:
    """The machine's CPU times (/proc/stat: user, nice, system, idle, iowait, irq, softirq, steal) and
    this process's and its children's CPU seconds, to tell the demo's own load from the rest."""
    try:
        with open("/proc/stat") as f:
            cpu = [int(x) for x in f.readline().split()[1:9]]
    except (OSError, ValueError):
        cpu = []
    own = [resource.getrusage(who) for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)]
    return cpu, [r.ru_utime + r.ru_stime for r in own]


def _load_figures(before: tuple, after: tuple, ticks: int) -> dict:
    """Where the machine's CPU went during the demo: busy (both ends included), stolen by the
    hypervisor (a virtual machine's CPU not run by its host), idle; and each end's CPU time per tick."""
    (c0, own0), (c1, own1) = before, after
    out = {"flight_cpu_ms_per_tick": 1e3 * (own1[0] - own0[0]) / max(ticks, 1),
           "pc_cpu_ms_per_tick": 1e3 * (own1[1] - own0[1]) / max(ticks, 1)}
    if len(c0) == len(c1) == 8 and sum(c1) > sum(c0):
        d = [b - a for a, b in zip(c0, c1)]
        total = sum(d)
        out.update(machine_busy_pct=100.0 * (total - d[3] - d[4] - d[7]) / total,
                   machine_steal_pct=100.0 * d[7] / total, machine_idle_pct=100.0 * (d[3] + d[4]) / total)
    return out


def check_times(args) -> None:
    """--seconds (demo: 0 < S <= MAX_DEMO_S; serve: also none, until the flight side ends), --cut AT FOR
    (each 0 to MAX_DEMO_S) and demo's --calibrate (run's range): nan, inf and negatives refused."""
    if args.seconds is not None and not 0 < args.seconds <= MAX_DEMO_S:
        raise InputError(f"--seconds {args.seconds:g}: above 0 to {MAX_DEMO_S:g} s")
    if args.cut and not all(0 <= v <= MAX_DEMO_S for v in args.cut):
        raise InputError(f"--cut {args.cut[0]:g} {args.cut[1]:g}: AT and FOR each 0 to {MAX_DEMO_S:g} s")
    lo, hi = CALIBRATE_RANGE_S
    if getattr(args, "calibrate", None) is not None and not lo <= args.calibrate <= hi:
        raise InputError(f"--calibrate {args.calibrate:g}: {lo:g} to {hi:g} s (as flightctl run's)")


def demo_main(args) -> int:
    check_times(args)
    if args.json:
        output_file(args.json, "--json", ".json")
    params = load(args.params)
    # The motor-loss gain schedule, solved once per vehicle and process (control/spin.py), before the link
    # opens: the PC side gives up on a flight side silent for IDLE_S once the first command has come.
    SpinController(params)
    stop = threading.Event()
    with tempfile.TemporaryDirectory(prefix="flightctl-hil-") as tmpdir:
        tmp = Path(tmpdir)
        before = _machine()
        try:
            proc, spec, fds = _spawn_serve(args, tmp)
        except BoardUnavailable as e:
            print(f"flightctl hil demo: cannot open the hil board: {e}", file=sys.stderr)
            return 3
        try:
            try:
                board = open_board("hil", params, BoardOptions(link=spec))
            except BoardUnavailable as e:
                print(f"flightctl hil demo: cannot open the hil board: {e}", file=sys.stderr)
                return 3
            link = board.hal.clock.link
            try:
                loop = FlightLoop(board.hal, params, demo_plan(args.seconds), calibrate_s=args.calibrate, stop=stop)
                loop.stop_reason = "interrupted (Ctrl-C)"
                reasons = prearm(board.hal, params, board.min_battery_v)

                def end_on_touchdown(i: int) -> None:   # the loop idles out a landing's margin: not here
                    events = loop.result.events
                    if events and events[-1][1].startswith("landed"):
                        loop.stop_reason = "landed"      # the flight's end, not a Ctrl-C
                        stop.set()
                loop.on_tick = end_on_touchdown
                result = loop.result
                if reasons:
                    outcome = "not armed: " + "; ".join(reasons)
                else:
                    try:
                        with ctrl_c_sets(stop):
                            result = loop.run()
                        outcome = next((w for _, w in reversed(result.events) if w.startswith("landed")), result.reason)
                    except ArmingRefused as e:           # the link went down on the ground: stay stopped
                        result = loop.result
                        outcome = f"not armed: {e}"
            finally:
                board.close()
            # The PC side ends on its own, however slowly: at the flight side's BYE, or when its end of the
            # link reads the end of file once every flight-side end is closed (hil/serve.py).
            for fd in fds:
                os.close(fd)
            fds = []
            proc.wait()
            after = _machine()
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
            for fd in fds:
                os.close(fd)
        pc_path = tmp / "serve.json"
        pc = json.loads(pc_path.read_text()) if pc_path.exists() else None
    pi = link.summary()
    if pc is None:
        raise InputError("hil demo: the PC side ended without its figures")
    sent = pi["commands_sent"] + pc["frames_sent"]
    lost = (pi["commands_sent"] - pc["rx"]["frames"]) + (pc["frames_sent"] - pi["rx_frames"])
    figures = {"frames_sent": sent, "frames_lost": lost, "latency_p50_ms": pi["latency_p50_ms"],
               "latency_p99_ms": pi["latency_p99_ms"], "latency_max_ms": pi["latency_max_ms"],
               "jitter_ms": pi["jitter_ms"], "stale_ticks": pi["stale_ticks"], "overruns": board.hal.clock.overruns,
               "outcome": outcome, "events": [f"{t:.3f} s: {what}" for t, what in result.events],
               "link_events": pi["events"], "link": args.link, "mode": args.mode,
               "max_alt_m": pc["max_alt_m"], "final_alt_m": pc["final_alt_m"], "crashed": pc["crashed"],
               "pc_turnaround_p50_ms": pc["turnaround_p50_ms"], "pc_turnaround_p99_ms": pc["turnaround_p99_ms"],
               **_load_figures(before, after, pi["commands_sent"]), "flight_side": pi, "pc_side": pc}
    steal = figures.get("machine_steal_pct")
    print(f"hil demo ({args.link}, {args.mode}): {sent} frames sent, {lost} lost; latency p50 "
          f"{figures['latency_p50_ms']:.2f} ms, p99 {figures['latency_p99_ms']:.2f} ms (the PC side's part: "
          f"p50 {figures['pc_turnaround_p50_ms']:.2f} ms, p99 {figures['pc_turnaround_p99_ms']:.2f} ms), jitter "
          f"{figures['jitter_ms']:.2f} ms; {figures['stale_ticks']} ticks without a new frame; outcome: "
          f"{outcome}; max altitude {pc['max_alt_m']:.2f} m, final {pc['final_alt_m']:.2f} m"
          + (f"; machine CPU {figures['machine_busy_pct']:.0f} % busy, {steal:.0f} % stolen by the host"
             if steal is not None else ""))
    if args.json:
        write_atomic(args.json, json.dumps(figures, indent=2) + "\n")
    if result.reason.startswith("stopped: interrupted"):
        print("flightctl hil demo: interrupted; the motors were stopped", file=sys.stderr)
        return EXIT_INTERRUPTED
    flew = outcome.startswith("landed") and not pc["crashed"] and pc["max_alt_m"] >= LEFT_GROUND_ALT
    if not flew:
        print(f"flightctl hil demo: the vehicle did not fly: {outcome}", file=sys.stderr)
    return 0 if flew else 1


def main(argv: list[str]) -> int:
    args = _parser().parse_args(argv)
    return serve_main(args) if args.what == "serve" else demo_main(args)
