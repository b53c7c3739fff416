"""What diagnose takes from a log's metadata (docs/real-flights.md): a vehicle that is not the paper's
(`# vehicle: foreign`, its `# rotors:`) has its base model identified from the flight; the filters
declared between the sensor and the logged gyro (`# gyro_filter:`) are applied to the model, so that
they are not named as actuation delay; motor outputs logged slower than the dynamics to judge
(`# motor_rate_hz:`) are judged for static effects only.

The flights are this project's simulator's (quick plan, full onboard path, noise on), with an effect
hidden in the plant drawn from a seeded generator, and rewritten as another autopilot would log them:
metadata lines added, the gyro filtered, the commands held. The truth is known; the diagnosis is not
told it."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from flightctl.cli import main
from helpers.diagnose_cases import close_enough, draw, quick_plan

PLUS_ROTORS = "1 0 -1; 0 1 1; -1 0 -1; 0 -1 1"   # the paper's + layout in arm lengths, spins (conventions.md)
MIN_AIRBORNE_S = 12.0


def fly(tmp: Path, cause: str | None, seed: int) -> tuple[Path, dict]:
    """A quick flight with `cause` hidden at a size drawn from the seeded generator, drawn again while
    the flight leaves less than MIN_AIRBORNE_S in the air (a lag can crash Table 6 through the full
    path at once: seconds of data, most of them tumbling)."""
    rng = np.random.default_rng(seed)
    while True:
        parameters = draw(rng, cause)[1] if cause else {}
        log = tmp / f"flight_{cause}_{seed}.csv"
        hidden = ["--effect", f"{cause}:" + ",".join(f"{k}={v!r}" for k, v in parameters.items())] if cause else []
        main(["sim", "--plan", str(quick_plan(tmp)), "--log", str(log), "--seed", str(seed), "--no-plot",
              "--quiet", *hidden])
        if airborne_s(log) >= MIN_AIRBORNE_S:
            return log, parameters


def airborne_s(log: Path) -> float:
    """Seconds above 0.1 m by the simulator's truth column (the test's knowledge, not the diagnosis')."""
    text = log.read_text().splitlines()
    head = next(i for i, line in enumerate(text) if not line.startswith("#"))
    names = text[head].split(",")
    t, z = names.index("t"), names.index("true_z")
    rows = [line.split(",") for line in text[head + 1:]]
    up = [float(r[t]) for r in rows if float(r[z]) > 0.1]
    return up[-1] - up[0] if up else 0.0


def rewrite(src: Path, dst: Path, meta: list[str], columns=None) -> Path:
    """The log with metadata lines added before the header (each replacing a line of its key) and
    `columns(name, values) -> values` applied to each column."""
    keys = {f"# {m.split(':')[0]}:" for m in meta}
    text = [line for line in src.read_text().splitlines() if not line.startswith(tuple(keys))] if keys \
        else src.read_text().splitlines()
    head = next(i for i, line in enumerate(text) if not line.startswith("#"))
    names = text[head].split(",")
    rows = [line.split(",") for line in text[head + 1:]]
    if columns is not None:
        for j, name in enumerate(names):
            cells = [r[j] for r in rows]
            if all(cells):
                new = columns(name, np.array(cells, dtype=float))
                for r, v in zip(rows, new):
                    r[j] = f"{v:.7g}"
    dst.write_text("\n".join(text[:head] + [f"# {m}" for m in meta] + [text[head]] + [",".join(r) for r in rows]) + "\n")
    return dst


def diagnose(log: Path) -> dict:
    out = log.with_suffix(".json")
    assert main(["diagnose", str(log), "--json", str(out), "--quiet"]) == 0
    return json.loads(out.read_text())


@pytest.mark.parametrize("cause, seed", [("motor_lag", 41), (None, 42)])
def test_a_foreign_vehicle_has_its_base_model_identified_and_its_cause_named(tmp_path, cause, seed):
    log, truth = fly(tmp_path, cause, seed)
    report = diagnose(rewrite(log, tmp_path / "foreign.csv", ["vehicle: foreign", f"rotors: {PLUS_ROTORS}"]))
    base = report["base_model"]
    assert base["identified"]
    # the simulated propeller: f = h1 (P - h2)^2 with h1 = 1.49e-3 N, h2 = 120, M = 1.645 kg (conventions.md)
    assert base["h2"]["value"] == pytest.approx(120.0, abs=5.0)
    assert base["k_z"]["value"] == pytest.approx(1.49e-3 / 1.645, rel=0.15)
    named = [c["cause"] for c in report["causes"]]
    if cause is None:
        assert named == []
    else:
        assert named == [cause]
        ok, tolerance = close_enough(cause, truth, report["parameters"])
        assert ok, f"{cause}: drawn {truth}, recovered {report['parameters']} ({tolerance})"


def test_a_declared_gyro_filter_is_modelled_and_not_named_as_actuation_delay(tmp_path):
    log, _ = fly(tmp_path, None, 43)
    hz = 20.0            # a PT1 of 8 ms, as a Betaflight gyro low-pass at its lowest settings
    a = math.exp(-2.0 * math.pi * hz / 450.0)

    def filtered(name, x):
        return signal.lfilter([1.0 - a], [1.0, -a], x, zi=[a * x[0]])[0] if name.startswith("gyro_") else x

    silent = diagnose(rewrite(log, tmp_path / "undeclared.csv", [], filtered))
    # undeclared, the filter is the gyro's own lag (docs/diagnose.md, "The rate path"), not the actuation's
    assert [c["cause"] for c in silent["causes"]] == ["gyro_lag"], silent["causes"]
    tau = 1.0 / (2.0 * math.pi * hz)
    assert abs(silent["parameters"]["tau"] - tau) <= 0.15 * tau + 0.002, (silent["parameters"], tau)
    chip = next(line.split(": ", 1)[1] for line in log.read_text().splitlines() if line.startswith("# gyro_filter:"))
    declared = diagnose(rewrite(log, tmp_path / "declared.csv", [f"gyro_filter: {chip}; pt1 {hz:g}"], filtered))
    assert declared["causes"] == []


def test_motor_outputs_logged_slowly_are_judged_for_static_effects_only(tmp_path):
    log, truth = fly(tmp_path, "com_offset", 44)
    rate = 10.0           # PX4's default actuator_outputs rate
    t = None

    def held(name, x):
        nonlocal t
        if name == "t":
            t = x
        if name in ("P1", "P2", "P3", "P4"):
            k = np.floor((t - t[0]) * rate).astype(int)
            first = np.searchsorted(k, k)               # the first row of each 1/rate interval
            return x[first]
        return x

    report = diagnose(rewrite(log, tmp_path / "slow.csv", [f"motor_rate_hz: {rate:g}"], held))
    assert {n["cause"] for n in report["not_judged"]} >= {"motor_lag", "actuation_delay", "motor_dynamics"}
    assert report["data"]["lowpass_hz"] == pytest.approx(rate / 4.0)
    assert report["cause"] == "com_offset"
    assert math.hypot(report["parameters"]["dx"] - truth["dx"], report["parameters"]["dy"] - truth["dy"]) < 0.003
