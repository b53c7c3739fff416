"""Every cause, not only the strongest (docs/measured-data.md, "Every cause"): two effects hidden in the
simulated plant at once, a pair and their sizes drawn from a seeded generator, are both named and
sized, and nothing else; the chain's entries are each fitted on top of the ones before it.

The pair is drawn from the contract's causes, less the twins (`motor_lag` and `motor_dynamics` are one
rotor lag modelled two ways: a vehicle has one or the other); the project's `gyro_lag` is paired in a
test of its own. A flight that leaves less than
MIN_AIRBORNE_S in the air (many lags crash Table 6 through the full path) is too short to judge two
causes: the pair is drawn again. Neither the pair nor the redraws are told to the diagnosis."""
from __future__ import annotations

import numpy as np
import pytest

from helpers.diagnose_cases import CONTRACT, close_enough, fly_pair

TIMING = ("motor_lag", "actuation_delay", "motor_dynamics")


def check_named(truth, report):
    """Both causes named and sized within their single-effect tolerances, and nothing else; the chain's
    entries each gain over the model before them."""
    named = {c["cause"]: c["parameters"] for c in report["causes"]}
    assert set(named) == set(truth), (truth, report["causes"])
    for cause, parameters in truth.items():
        ok, tolerance = close_enough(cause, parameters, named[cause])
        assert ok, f"{cause}: drawn {parameters}, recovered {named[cause]} (tolerance: {tolerance})"
    # the contract's top level is the chain's first entry; each entry gains over the model before it
    first = report["causes"][0]
    assert (report["cause"], report["parameters"], report["gain"]) == (first["cause"], first["parameters"],
                                                                       first["gain"])
    for c in report["causes"]:
        assert c["gain"] > 0 and c["rmse_after"] < c["rmse_before"]


def check_pair(truth, report):
    """`check_named`, and the second entry starts from the first's held-out RMSE (its model folded in)."""
    check_named(truth, report)
    assert report["causes"][1]["rmse_before"] == pytest.approx(report["causes"][0]["rmse_after"], rel=0.05)


@pytest.mark.parametrize("seed", [3, 4, 5])
def test_two_hidden_effects_are_both_named_and_sized_and_nothing_else(tmp_path, seed):
    check_pair(*fly_pair(tmp_path, np.random.default_rng(seed)))


@pytest.mark.parametrize("seed", [3, 4])
def test_a_gyro_lag_beside_a_cause_that_does_not_time_the_rotors_is_named_with_it(tmp_path, seed):
    """The project's `gyro_lag` with a partner drawn from the contract's causes less the three that time
    the actuation: beside one of those the first timing fit takes up both lags (docs/diagnose.md)."""
    check_pair(*fly_pair(tmp_path, np.random.default_rng(seed), tuple(c for c in CONTRACT if c not in TIMING),
                         first="gyro_lag"))


@pytest.mark.parametrize("lag,seed", [("motor_lag", 7), ("motor_lag", 201), ("gyro_lag", 7)])
def test_a_lag_beside_rotor_inflow_is_named_as_the_lag_it_is(tmp_path, lag, seed):
    """A lag of the rotors and a lag of the gyro are look-alikes (docs/diagnose.md, "Two lags at once"):
    only the rotors' lags the accelerometer's z. Beside `rotor_inflow`, which moves `acc_z` too, the
    first round alone can take one for the other; the chain, which weighs them with the other causes in
    the model, must name the one hidden, with `rotor_inflow`, both sized, and nothing else. Sizes drawn
    from the single-effect ranges; neither the pair nor the sizes are told to the diagnosis. (Of these
    draws, the first round alone names the other look-alike in motor_lag's 201 and gyro_lag's 7.)"""
    truth, report = fly_pair(tmp_path, np.random.default_rng(seed), (lag,), first="rotor_inflow")
    assert set(truth) == {"rotor_inflow", lag}
    # both named and sized, and no look-alike of the lag (not `check_pair`: with a lag of tens of ms
    # the first cause folded in at its fit on all the data predicts much better than its held-out score)
    check_named(truth, report)
    if lag == "motor_lag":
        # why the first round alone can miss it: in acc_z, the lag's term and the inflow's, at the sizes drawn,
        # are in antiphase (docs/diagnose.md), so the lag's fit alone spoils that channel
        lag_z, inflow_z = acc_z_terms(report["data"]["files"][0], truth)
        assert np.corrcoef(lag_z, inflow_z)[0, 1] < 0


def acc_z_terms(log: str, truth: dict) -> tuple[np.ndarray, np.ndarray]:
    """The filtered change of the predicted acc_z of `motor_lag` and of `rotor_inflow` at the drawn sizes."""
    from flightctl.params import load
    from flightctl.sim.causes import CAUSES
    from flightctl.sim.diagnose.cli import read_logs
    from flightctl.sim.diagnose.data import load_file
    from flightctl.sim.diagnose.dataset import CHANNELS, LOWPASS_HZ, DataSet, Vehicle
    a = load(None).airframe
    f = load_file(read_logs([log], None, lambda *_: None)[0], a)
    ds = DataSet([f], Vehicle.known(a, f.layout), LOWPASS_HZ)
    z = CHANNELS.index("acc_z")
    return tuple(CAUSES[c].candidate(ds).predict(truth[c])[z] for c in ("motor_lag", "rotor_inflow"))
