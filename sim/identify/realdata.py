"""Real thrust-stand data against the paper's propeller method: the RCbenchmark adapter and the report.

The paper (sec. 3.2.1) has no torque sensor: it takes the reaction torque from electrical power,
`tau = V I / w` (eq. 13-16), and assumes `f = c1 w^2` (eq. 27). The RCbenchmark 1580 stand measures
the reaction torque, and the UIUC static tests give the thrust coefficient over speed, so both
assumptions can be held against measurements. `flightctl identify real-data --out docs` regenerates
the figures (realplots.py, which imports this module, never the reverse) and the block of numbers in
docs/identification.md.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from flightctl.errors import InputError

from flightctl.files import output_dir, write_atomic
from flightctl.logfile import BENCH_COLUMNS, read_table
from flightctl.params import Airframe
from flightctl.physics import G
from flightctl.sim.docs import table as _table
from flightctl.sim.identify.fits import rms
from flightctl.sim.identify.propeller import torque_from_power

RCB = {"esc": "ESC signal (µs)", "torque": "Torque (N·m)", "thrust": "Thrust (gf)",
       "voltage": "Voltage (V)", "current": "Current (A)", "rpm": "Motor Electrical Speed (RPM)"}
RCB_RANGES = {"esc": (0.0, 1e4), "torque": (-100.0, 100.0), "thrust": (-1e5, 1e5), "voltage": (0.0, 100.0),
              "current": (-10.0, 1e3), "rpm": (0.0, 1e6)}
GF = G * 1e-3                   # N per gram-force
RPM = 2 * np.pi / 60            # rad/s per rev/min
ESC_HZ = Airframe().esc_pwm_hz  # 449 Hz: P = pulse_s * 449 * 255 (conventions.md)
ESC_OFF_US = 1000.0             # at or below this pulse width the ESC holds the motor off
UIUC_COLUMNS = ("volume", "PropName", "D_in", "N_rpm", "CT")
LARGE_IN = 11.0                 # propellers this large (inches) or more are like the reference 12-inch one
MIN_STEPS = 9                   # steps a run needs to hold out a third and still fit every model
BEGIN, END = "<!-- real-data:begin -->", "<!-- real-data:end -->"
FIGURE_FILES = {"torque": "real_torque.png", "ct": "real_ct.png", "held_out": "real_heldout.png"}  # realplots.py


@dataclass(frozen=True)
class Run:
    """One RCbenchmark file as bench points: one per steady ESC step, SI units."""
    name: str
    rows: int
    P: np.ndarray
    thrust: np.ndarray
    omega: np.ndarray
    voltage: np.ndarray
    current: np.ndarray
    torque: np.ndarray  # measured reaction torque, signed so that it is positive for this spin direction

    @property
    def steps(self) -> int:
        return len(self.P)


def read_rcbenchmark(path: str | Path) -> Run:
    """Keep the rows with a speed reading and the ESC above its off pulse; average consecutive rows at
    the same pulse width (one steady step); convert µs -> P at 449 Hz, gf -> N, RPM -> rad/s."""
    table = read_table(path, tuple(RCB.values()), allow_missing=(RCB["rpm"],))
    for key, (lo, hi) in RCB_RANGES.items():   # the stand's own ranges: beyond them a row is not a reading
        x = table[RCB[key]]
        bad = np.flatnonzero(~((x >= lo) & (x <= hi)) & ~np.isnan(x))
        if bad.size:
            table.fail(f"{x[bad[0]]:g} is outside {lo:g} to {hi:g}", row=int(bad[0]), column=RCB[key])
    esc, rpm = table[RCB["esc"]], table[RCB["rpm"]]
    keep = (rpm > 0) & (esc > ESC_OFF_US)
    step = np.concatenate([[0], np.cumsum(np.diff(esc) != 0)])
    ids = np.unique(step[keep])

    def mean(column: str) -> np.ndarray:
        x = table[RCB[column]]
        return np.array([x[keep & (step == i)].mean() for i in ids])
    torque = mean("torque")
    sign = -1.0 if torque.size and np.median(torque) < 0 else 1.0
    return Run(Path(path).name, len(table), P=mean("esc") * 1e-6 * ESC_HZ * 255, thrust=mean("thrust") * GF,
               omega=mean("rpm") * RPM, voltage=mean("voltage"), current=mean("current"), torque=sign * torque)


def convert(paths: list[str], out: str) -> list[str]:
    """RCbenchmark files -> one bench.csv (docs/measured-data.md), file i as motor i."""
    if len(paths) > 4:
        raise InputError(f"at most 4 runs (motors 1-4), got {len(paths)}")
    runs = [read_rcbenchmark(p) for p in paths]
    for path, run in zip(paths, runs):
        if not run.steps:
            raise InputError(f"{path}: no row with a speed reading and the ESC above {ESC_OFF_US:g} µs")
    if not Path(out).resolve().parent.is_dir():
        raise InputError(f"{out}: cannot write, no directory {Path(out).resolve().parent}")
    lines = [f"# source: converted from RCbenchmark exports, motor i = file i; P = pulse * {ESC_HZ:g} Hz * 255"]
    lines += [f"# motor {m}: {p}" for m, p in enumerate(paths, 1)]
    lines.append(",".join(BENCH_COLUMNS))
    for m, r in enumerate(runs, 1):
        lines += [f"{m},{P:.6g},{f:.6g},{w:.6g},{V:.6g},{I:.6g}"
                  for P, f, w, V, I in zip(r.P, r.thrust, r.omega, r.voltage, r.current)]
    write_atomic(out, "\n".join(lines) + "\n")
    return [f"motor {m}: {p}: {r.steps} steady steps from {r.rows} rows" for m, (p, r) in enumerate(zip(paths, runs), 1)]


# ---- the analyses ---------------------------------------------------------------------------------

def efficiency(run: Run) -> np.ndarray:
    """Measured mechanical power over electrical power, tau w / (V I): what eq. 16 takes to be 1."""
    return run.torque * run.omega / (run.voltage * run.current)


def held_out(speed: np.ndarray, split: str) -> np.ndarray:
    """Mask of the held-out points of a sweep in step order: every third step ('interleaved') or the
    fastest third ('extrapolation')."""
    n = len(speed)
    if split == "interleaved":
        return np.arange(n) % 3 == 1
    return np.argsort(np.argsort(speed)) >= n - n // 3


SPLITS = ("interleaved", "extrapolation")
THRUST_MODELS = {  # name: columns of f = columns @ theta
    "c1 w^2 (eq. 27)": lambda w: w[:, None] ** 2,
    "c1 w^2 + c2 w": lambda w: np.column_stack([w ** 2, w]),
    "c1 w^2 + c3 w^3 (CT linear in w)": lambda w: np.column_stack([w ** 2, w ** 3]),
}
BASE_THRUST, EXT_THRUST = "c1 w^2 (eq. 27)", "c1 w^2 + c2 w"


def lstsq(A: np.ndarray, y: np.ndarray) -> np.ndarray:
    return np.linalg.lstsq(A, y, rcond=None)[0]


def losses(run: Run) -> np.ndarray:
    """Electrical power not turned into reaction torque: V I - tau w (W)."""
    return run.voltage * run.current - run.torque * run.omega


def thrust_predictions(w, f, test) -> dict[str, np.ndarray]:
    """Each thrust model fitted on the points not in `test`, predicted at the held-out points."""
    out = {}
    for name, columns in THRUST_MODELS.items():
        A = columns(w)
        out[name] = A[test] @ lstsq(A[~test], f[~test])
    return out


LOSS_MODELS = {  # name: columns of the loss V I - tau w = columns @ theta
    "loss R I^2 + P0": lambda run: np.column_stack([run.current ** 2, np.ones(run.steps)]),
    "loss R I^2 + k w + P0": lambda run: np.column_stack([run.current ** 2, np.ones(run.steps), run.omega]),
}
SPEED_LOSS = "loss R I^2 + k w + P0"
BASE_TORQUE, EXT_TORQUE = "paper: eq. 28 on V I / w", "loss R I^2 + P0"
SENSOR_TORQUE = "eq. 28 on the torque sensor"


def torque_predictions(run: Run, test) -> dict[str, np.ndarray]:
    """The paper's pipeline (eq. 28 fitted to V I / w, no torque sensor) against loss models fitted to the
    measured torque of the training steps, `tau = (V I - loss) / w`, and against eq. 28 fitted to the
    measured torque itself; all predicted at the held-out steps."""
    tau_e = torque_from_power(run.voltage, run.current, run.omega)
    g1, g2 = np.polyfit(run.thrust[~test], tau_e[~test], 1)
    out = {BASE_TORQUE: g1 * run.thrust[test] + g2}
    g1, g2 = np.polyfit(run.thrust[~test], run.torque[~test], 1)
    out[SENSOR_TORQUE] = g1 * run.thrust[test] + g2
    loss = losses(run)
    for name, columns in LOSS_MODELS.items():
        A = columns(run)
        out[name] = (run.voltage * run.current - A @ lstsq(A[~test], loss[~test]))[test] / run.omega[test]
    return out


def ct_change(speed: np.ndarray, ct: np.ndarray) -> float:
    """Relative change of a thrust coefficient over the tested speeds, from a straight-line fit."""
    slope = np.polyfit(speed, ct, 1)[0]
    return float(slope * (speed.max() - speed.min()) / ct.mean())


def read_uiuc(path: Path) -> dict[str, tuple[np.ndarray, np.ndarray, float]]:
    """Propeller -> (RPM, CT, diameter in inches), sorted by speed; a propeller is one name in one data volume."""
    table = read_table(path, UIUC_COLUMNS, text_columns=("PropName",))
    keys = np.array([f"{name} (vol. {v:g})" for name, v in zip(table["PropName"], table["volume"])])
    props = {}
    for key in dict.fromkeys(keys):
        k = keys == key
        order = np.argsort(table["N_rpm"][k])
        props[str(key)] = (table["N_rpm"][k][order], table["CT"][k][order], float(table["D_in"][k][0]))
    return props


def analyse(data: Path) -> dict:
    runs = [read_rcbenchmark(p) for p in sorted((data / "rcbenchmark").glob("*.csv"))]
    used = [r for r in runs if r.steps >= MIN_STEPS]
    res: dict = {"skipped": [(r.name, r.rows, r.steps) for r in runs if r.steps < MIN_STEPS], "runs": {}}
    for r in used:
        eta = efficiency(r)
        k_f = r.thrust / r.omega ** 2
        tau_e = torque_from_power(r.voltage, r.current, r.omega)
        one = {"steps": r.steps, "volts": float(np.median(r.voltage)), "rpm": (r.omega.min() / RPM, r.omega.max() / RPM),
               "eta": eta, "eta_min": float(eta.min()), "eta_median": float(np.median(eta)), "eta_max": float(eta.max()),
               "g1_ratio": float(np.polyfit(r.thrust, tau_e, 1)[0] / np.polyfit(r.thrust, r.torque, 1)[0]),
               "kf_change": ct_change(r.omega, k_f),
               # fitted to all steps: (c1, c2); (R, P0); (R, P0, k)
               "c2": lstsq(THRUST_MODELS[EXT_THRUST](r.omega), r.thrust)[1],
               "loss": lstsq(LOSS_MODELS[EXT_TORQUE](r), losses(r)),
               "loss_speed": lstsq(LOSS_MODELS[SPEED_LOSS](r), losses(r)),
               "rmse": {}}
        for split in SPLITS:
            test = held_out(r.omega, split)
            one["rmse"][split] = {
                **{m: rms(p - r.thrust[test]) for m, p in thrust_predictions(r.omega, r.thrust, test).items()},
                **{m: rms(p - r.torque[test]) for m, p in torque_predictions(r, test).items()}}
        res["runs"][r.name] = one
    res["run_data"] = used
    props = read_uiuc(data / "uiuc-static" / "static_tests.csv")
    uiuc = {"change": [], "rel": {m: [] for m in THRUST_MODELS}, "curves": props,
            "large": np.array([d >= LARGE_IN for _rpm, _ct, d in props.values()])}
    for rpm, ct, _d in props.values():
        uiuc["change"].append(ct_change(rpm, ct))
        w, f = rpm * RPM, ct * rpm ** 2  # thrust up to the constant rho D^4 / 3600
        test = held_out(w, "interleaved")
        for m, p in thrust_predictions(w, f, test).items():
            uiuc["rel"][m].append(rms(p / f[test] - 1))
    uiuc["change"] = np.array(uiuc["change"])
    uiuc["rel"] = {m: np.array(v) for m, v in uiuc["rel"].items()}
    res["uiuc"] = uiuc
    return res


# ---- the report -----------------------------------------------------------------------------------

def report_dirs(data: str | None, out: str) -> tuple[Path, Path]:
    """The real data (`--data`, default ../shared/data/real beside the checkout the command runs in)
    and the output directory, checked."""
    from flightctl.sim.checkout import shared_real_data
    data_dir = Path(data) if data else shared_real_data()
    if data_dir is None:
        raise InputError("not in a checkout of flightctl: give the real data with --data DIR (../shared/data/real)")
    if not (data_dir / "rcbenchmark").is_dir() or not (data_dir / "uiuc-static").is_dir():
        raise InputError(f"{data_dir}: no rcbenchmark/ and uiuc-static/ here; give the real data with --data DIR")
    out_dir = Path(out)
    if not out_dir.is_dir():
        raise InputError(f"--out {out}: not a directory")
    output_dir(out_dir, "--out")             # one this user may write in, before the analysis
    return data_dir, out_dir


def write_report(res: dict, images: dict[str, bytes], data: str | None, out_dir: Path) -> list[str]:
    """Write the figures (file name -> PNG, drawn by realplots.py) and the generated block of
    OUT/identification.md."""
    block = markdown(res, data)
    for name, image in images.items():
        write_atomic(out_dir / name, image)
    doc = out_dir / "identification.md"
    from flightctl.sim.docs import replace
    text = doc.read_text() if doc.exists() else ""
    inner = block.removeprefix(BEGIN).removesuffix(END).strip("\n")
    new = replace(text, BEGIN, END, inner)
    write_atomic(doc, new if new is not None else text + ("\n" if text else "") + block + "\n")
    return [f"wrote {out_dir / n} ({len(b) // 1024} kB)" for n, b in images.items()] + \
           [f"wrote the real-data block of {doc}", *summary(res)]


def summary(res: dict) -> list[str]:
    eta = np.concatenate([r["eta"] for r in res["runs"].values()])
    return [f"efficiency tau w / (V I) over {len(eta)} steps of {len(res['runs'])} files: "
            f"median {np.median(eta):.2f}, range {eta.min():.2f} to {eta.max():.2f}",
            f"UIUC CT change over the tested speeds, median of {len(res['uiuc']['change'])} propellers: "
            f"{100 * np.median(res['uiuc']['change']):+.1f} %", *verdicts(res)]


def verdicts(res: dict) -> list[str]:
    """Held-out RMSE: extended against base model, per split."""
    lines = []
    for split in SPLITS:
        for base, ext in ((BASE_THRUST, EXT_THRUST), (BASE_TORQUE, EXT_TORQUE)):
            b = np.array([r["rmse"][split][base] for r in res["runs"].values()])
            e = np.array([r["rmse"][split][ext] for r in res["runs"].values()])
            lines.append(f"{split}: {ext} beats {base} in {np.sum(e < b)} of {len(b)} files, "
                         f"median gain 1 - RMSE_ext / RMSE_base = {np.median(1 - e / b):.2f}")
    return lines


def markdown(res: dict, data: str | None) -> str:
    runs = res["runs"]
    command = "flightctl identify real-data --out docs" + (f" --data {data}" if data else "")
    short = {name: name.removeprefix("StepsTest_").removesuffix(".csv") for name in runs}
    eta = np.concatenate([r["eta"] for r in runs.values()])
    u = res["uiuc"]
    lines = [BEGIN, f"<!-- generated by `{command}`; do not edit by hand -->", "",
             f"Generated by `{command}` from the repository root.", "",
             f"RCbenchmark files used: {len(runs)} (one point per ESC step); skipped: "
             + ", ".join(f"{n} ({rows} rows, {steps} steps with a speed reading)" for n, rows, steps in res["skipped"])
             + ". UIUC: " + f"{len(u['change'])} propeller sweeps.", "",
             "#### (a) Torque from electrical power (eq. 13-16) against the torque sensor", "",
             f"Efficiency `eta = tau_meas w / (V I)` over all {len(eta)} steps: median **{np.median(eta):.2f}**, "
             f"range {eta.min():.2f} to {eta.max():.2f}; so `V I / w` overstates the reaction torque by a factor "
             f"{1 / np.median(eta):.1f} at the median step and by up to {1 / eta.min():.0f} at the slowest steps. "
             "`g1 ratio` is the slope of eq. 28 fitted to `V I / w` over the slope fitted to the measured torque, "
             f"median **{np.median([r['g1_ratio'] for r in runs.values()]):.2f}**: the excess is mostly an offset "
             "(large `g2`), and the slope, which is all that yaw control sees (g2 cancels in "
             "`tau_psi = tau_1 - tau_2 + tau_3 - tau_4`), comes out too small. "
             "`R`, `P0` are the loss model `V I = tau w + R I^2 + P0` fitted to all steps of the file.", "",
             *_table(["file", "steps", "V", "RPM", "eta min", "eta median", "eta max", "g1 ratio", "R (ohm)", "P0 (W)"],
                     [[short[n], str(r["steps"]), f"{r['volts']:.1f}", f"{r['rpm'][0]:.0f}-{r['rpm'][1]:.0f}",
                       f"{r['eta_min']:.2f}", f"{r['eta_median']:.2f}", f"{r['eta_max']:.2f}", f"{r['g1_ratio']:.2f}",
                       f"{r['loss'][0]:.2f}", f"{r['loss'][1]:.1f}"]
                      for n, r in runs.items()]), "",
             f"![torque]({FIGURE_FILES['torque']})", "",
             "#### (b) Thrust coefficient over speed (eq. 27 assumes it constant)", "",
             f"UIUC: CT changes over each propeller's tested speeds by a median **{100 * np.median(u['change']):+.1f} %** "
             f"(5th to 95th percentile {100 * np.percentile(u['change'], 5):+.1f} % to "
             f"{100 * np.percentile(u['change'], 95):+.1f} %); more than 5 % for "
             f"{100 * np.mean(np.abs(u['change']) > 0.05):.0f} % of the propellers; for the {np.sum(u['large'])} "
             f"propellers of {LARGE_IN:g} inches or more (the reference airframe flies 12-inch ones) the median is "
             f"{100 * np.median(u['change'][u['large']]):+.1f} %. "
             "RCbenchmark: `f / w^2` changes from the slowest to the fastest step by a median "
             f"**{100 * np.median([r['kf_change'] for r in runs.values()]):+.1f} %** "
             "(straight-line fit over speed, relative to the mean); fitted to all steps, `f = c1 w^2 + c2 w` has "
             f"`c2 < 0` in {sum(r['c2'] < 0 for r in runs.values())} of {len(runs)} files.", "",
             "UIUC held out every third speed, relative thrust RMSE, median over propellers: "
             + ", ".join(f"{m} **{100 * np.median(v):.1f} %**" for m, v in u["rel"].items()) + ".", "",
             f"![CT]({FIGURE_FILES['ct']})", "",
             "#### (c) Extended models scored on held-out steps", "",
             "Each file is fitted without its held-out steps and scored on them: `interleaved` holds out every "
             "third ESC step, `extrapolation` holds out the fastest third. Thrust RMSE in mN, torque RMSE in mN m. "
             f"The torque baseline is the paper's pipeline (eq. 28 fitted to `V I / w`, no torque sensor); "
             f"`{EXT_TORQUE}` fits `V I = tau w + R I^2 + P0` to the training steps' measured torque; "
             f"`{SENSOR_TORQUE}` refits eq. 28 to the torque sensor. Fitted to all steps, `{SPEED_LOSS}` gives a "
             f"negative R in {sum(r['loss_speed'][0] < 0 for r in runs.values())} of {len(runs)} files.", ""]
    models = [*THRUST_MODELS, BASE_TORQUE, *LOSS_MODELS, SENSOR_TORQUE]
    for split in SPLITS:
        lines += [f"`{split}`:", ""]
        lines += _table(["file", *models],
                        [[short[n], *(f"{1e3 * r['rmse'][split][m]:.3g}" for m in models)] for n, r in runs.items()])
        lines.append("")
    lines += ["In words: " + "; ".join(verdicts(res)) + ".", "", f"![held-out]({FIGURE_FILES['held_out']})", END]
    return "\n".join(lines)
