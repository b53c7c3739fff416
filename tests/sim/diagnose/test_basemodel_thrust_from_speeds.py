"""The thrust effectiveness from the log's own rotor speeds (basemodel.thrust_from_speeds, eq. 27: f = c1 Omega^2),
on the INDIflight logs that measured them (../shared/data/real/flights/indiflight, omegaUnfiltered):
it agrees with the one the motor commands give where both are identified, and it is what identifies the
thrust of a flight whose commands do not show it (the regression of issue 35: two Betaflight 4.5.1
flights with eRPM were refused as not identifying their thrust, though acc_z regressed on the sum of the
squared rotor speeds is positive in every block; no public Betaflight log with eRPM and a license for
tests was found, so the INDIflight logs stand in, their commands' collective part removed)."""
from __future__ import annotations

import numpy as np
import pytest

from flightctl.errors import InputError
from flightctl.logfile import read_flight_log
from flightctl.params import Airframe
from flightctl.sim.diagnose.basemodel import T_BASE, identify
from flightctl.sim.diagnose.data import FOREIGN_COLUMNS, load_file
from flightctl.sim.diagnose.dataset import LOWPASS_HZ
from flightctl.sim.diagnose.rotorspeed import rotor_speed_lag
from flightctl.cli import main
from helpers.real import INDIFLIGHT, need, rows_and_header, write

pytest.importorskip("orangebox")


def _csv(tmp_path, name):
    out = tmp_path / f"{name}.csv"
    assert main(["log", "import", str(need(INDIFLIGHT / name)), str(out), "--quiet"]) == 0
    return out


def _identify(path):
    f = load_file(read_flight_log(str(path), extra=FOREIGN_COLUMNS), Airframe())
    speeds = rotor_speed_lag([f])
    return identify([f], LOWPASS_HZ, lambda *_: None, speeds)[0].identification, speeds


@pytest.mark.parametrize("name", ["LOG00258.BFL", "LOG00259.BFL"])
def test_the_thrust_from_the_rotor_speeds_agrees_with_the_commands(tmp_path, name):
    csv = _csv(tmp_path, name)
    base, speeds = _identify(csv)
    k = base["k_z"]
    assert k["source"].startswith("the log's rotor speeds") and k["value"] > T_BASE * k["stderr"]
    # the commands' own fit, without the speeds (the same flight, the same h2 from its speeds)
    f = load_file(read_flight_log(str(csv), extra=FOREIGN_COLUMNS), Airframe())
    alone = identify([f], LOWPASS_HZ, lambda *_: None, {**speeds, "slope": 0.0})[0].identification["k_z"]
    assert alone["source"].startswith("the motor commands")
    assert abs(k["value"] - alone["value"]) < 2.0 * np.hypot(k["stderr"], alone["stderr"]), (k, alone)


@pytest.mark.parametrize("seed", [35, 36])
def test_a_flight_whose_commands_do_not_show_its_thrust_is_identified_from_its_rotor_speeds(tmp_path, seed):
    """LOG00259's commands with a collective part the motors did not follow added (the same slow noise,
    below 4 Hz, on all four, its size drawn at random, half the flight's own collective swing or so): the four
    still differ as they did, for the torques, but no longer say how hard the rotors pushed together; its
    rotor speeds and its IMU are as flown. The commands alone no longer identify the thrust (refused, as the
    Betaflight 4.5.1 flights were); the speeds do."""
    from scipy import signal
    csv = _csv(tmp_path, "LOG00259.BFL")
    meta, names, rows = rows_and_header(csv.read_text())
    cols = [names.index(f"P{i}") for i in range(1, 5)]
    P = np.array([[float(r[j]) for j in cols] for r in rows])
    t = np.array([float(r[0]) for r in rows])
    on = (P > 10).all(axis=1)
    rng = np.random.default_rng(seed)
    noise = signal.sosfiltfilt(signal.butter(2, 4.0, fs=1.0 / float(np.median(np.diff(t))), output="sos"),
                               rng.standard_normal(t.size))
    size = rng.uniform(0.4, 0.6) * float(P.mean(axis=1)[on].std())
    P = np.where(on[:, None], np.clip(P + (size * noise / noise.std())[:, None], 0.0, 255.0), P)
    for r, p in zip(rows, P):
        for j, v in zip(cols, p):
            r[j] = f"{v:.4f}"
    path = write(meta, names, rows, tmp_path / "collective_noise.csv")
    f = load_file(read_flight_log(str(path), extra=FOREIGN_COLUMNS), Airframe())
    speeds = rotor_speed_lag([f])
    assert speeds["slope"] > 0                       # the commands still drive the speeds, less clearly
    try:
        alone = identify([f], LOWPASS_HZ, lambda *_: None, {**speeds, "slope": 0.0})[0].identification["k_z"]
        t_alone = alone["value"] / alone["stderr"]
    except InputError as e:                         # the commands alone: refused, naming the thrust
        assert "thrust" in str(e)
        t_alone = None
    base = identify([f], LOWPASS_HZ, lambda *_: None, speeds)[0].identification["k_z"]
    assert base["source"].startswith("the log's rotor speeds")
    t_speeds = base["value"] / base["stderr"]
    assert t_speeds > T_BASE and (t_alone is None or t_alone < t_speeds / 3), (t_alone, t_speeds)
    # per squared rotor speed (k_z over the speed-per-command slope squared) the flight as flown says the same
    flown, speeds0 = _identify(csv)
    per, per0 = (b["value"] / sp["slope"] ** 2 for b, sp in ((base, speeds), (flown["k_z"], speeds0)))
    err = np.hypot(base["stderr"] / speeds["slope"] ** 2, flown["k_z"]["stderr"] / speeds0["slope"] ** 2)
    assert abs(per - per0) < 2.0 * err, (per, per0, err)
