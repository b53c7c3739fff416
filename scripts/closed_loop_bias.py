"""Why the base model's effectiveness is too small on a flying loop (issue 42 part 1; docs/steps.md, "How far to
trust it"): per log (its first half, as `predict.held_out` identifies it) and rate axis, the angular acceleration
regressed on the model's commanded acceleration (basemodel.py's channel at the identified timing, both low-passed at
12 Hz forward and back over the airborne rows) by ordinary least squares (the direct fit: 1 by construction, up
to basemodel.py's weighting and rotor gains) and by two-stage least squares with the rate setpoint as the instrument
(its derivative, low-passed alike, delayed 0-80 ms: the setpoint is not fed back, the commands are), with the
first stage's R^2 (a weak instrument stays biased toward the direct fit); beside them the factor on the base
model's b that the loop fit (loopfit.py) finds on the same rows' measured steps, the identifying step error at
factor 1 and at the fit. A factor well above 1 by both routes is the feedback's bias toward zero.

    python scripts/closed_loop_bias.py [LOG ...]
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
FLIGHTS = ROOT / ".." / "shared" / "data" / "real" / "flights"
CS110 = ROOT / "tests" / "data" / "pid-analyzer"
DEFAULT = (CS110 / "example_smooth_tune.BBL", CS110 / "better_tune.BBL", FLIGHTS / "betaflight" / "btfl_002.bbl",
           FLIGHTS / "betaflight" / "LOG00037.BFL")
LAGS_MS = (0, 5, 10, 20, 40, 80)
KEY = {"x": "k_p", "y": "k_q", "z": "k_r"}


def iv(fd, first, vehicle, axis: str, tau: float) -> tuple[float, float, float]:
    """(OLS slope, 2SLS slope, first-stage R^2) of the measured on the model's angular acceleration."""
    from scipy import signal
    i = "xyz".index(axis)
    idn, lay = vehicle.identification, vehicle.layout
    fs = 1.0 / float(np.median(np.diff(fd.t)))
    sos = signal.butter(2, 12.0, fs=fs, output="sos")
    lp = lambda v: signal.sosfiltfilt(sos, v)
    lever = {"x": np.array(lay.y), "y": -np.array(lay.x), "z": -np.array(lay.spin, float)}[axis]
    P = np.nan_to_num(fd.P[:4])
    k = int(round(tau * fs))
    if k:
        P = np.concatenate([np.repeat(P[:, :1], k, axis=1), P[:, :-k]], axis=1)
    x = idn[KEY[axis]]["value"] * ((np.array(vehicle.gains) * lever)[:, None] * (P - idn["h2"]["value"]) ** 2).sum(axis=0)
    acc = np.zeros(fd.t.size)
    acc[:-1] = np.diff(fd.gyro[i]) / np.diff(fd.t)
    dsp = np.gradient(lp(np.interp(fd.t, first["t"], np.nan_to_num(first[f"setpoint_{axis}"]))), fd.t)
    air = fd.airborne
    X, Y = lp(x)[air], lp(acc)[air]
    Z = [np.concatenate([np.zeros(L), dsp[:dsp.size - L]])[air] for L in (int(round(m * 1e-3 * fs)) for m in LAGS_MS)]
    Z = np.column_stack(Z + [np.ones(X.size)])
    one = np.ones(X.size)
    ols = np.linalg.lstsq(np.column_stack([X, one]), Y, rcond=None)[0][0]
    xh = Z @ np.linalg.lstsq(Z, X, rcond=None)[0]
    tsls = np.linalg.lstsq(np.column_stack([xh, one]), Y, rcond=None)[0][0]
    return float(ols), float(tsls), float(1.0 - np.var(X - xh) / np.var(X))


def main(argv: list[str]) -> int:
    from flightctl import params as paramfile
    from flightctl.sim.diagnose import loopfit, predict
    from flightctl.sim.diagnose.data import load_file
    from flightctl.sim.logs import controller, read_foreign
    a = paramfile.load(None).airframe
    print("| log (first half) | axis | b direct | OLS slope | 2SLS slope (setpoint) | first-stage R^2 | loop fit factor "
          "| identifying step error: direct, fitted |")
    print("|---|---|---|---|---|---|---|---|")
    for path in [Path(p) for p in argv] or DEFAULT:
        tab = read_foreign(str(path))[0]
        ctrl = controller.of_table(tab)
        first = predict.halves(tab)[0]
        model = predict.base_model(first, a)
        if isinstance(model, str):
            print(f"| {path.name} | all | {model} |  |  |  |  |  |")
            continue
        vehicle, declared = model
        fit = loopfit.fit(vehicle, declared, first, ctrl)
        fd = load_file(first, a)
        tau = float(vehicle.identification["timing"]["value"])
        for axis in "xyz":
            e = fit["axes"].get(axis, {})
            if "why" in e:
                print(f"| {path.name} | {axis} |  |  |  |  |  | {e['why'].split('; fly next time')[0]} |")
                continue
            ols, tsls, r2 = iv(fd, first, vehicle, axis, tau)
            bound = " (at its bound)" if e["at_bound"] else ""
            print(f"| {path.name} | {axis} | {e['b_direct']:.4g} | {ols:.2f} | {tsls:.2f} | {r2:.2f} | "
                  f"{e['factor']:.3g}{bound}{'' if e['fitted'] else ' (kept: the direct fit agrees)'} | "
                  f"{e['step_error_direct']:.2f}, {e['step_error']:.2f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
