"""The grid fits of diagnose as they are made fast (docs/diagnose.md, "Speed"), on a real 1 kHz log: the
walk from every 4th grid point finds each fold's best point and the full data's as the whole grid does,
and a candidate's change of the prediction kept for the data set's model is the one it computes anew,
shared by a copy that carries one more term and not by one whose model changed; rotor_drag's, the
files' alone, is kept across models and is what each computes anew."""
from __future__ import annotations

import copy

import numpy as np
import pytest

from flightctl.cli import main
from flightctl.logfile import read_flight_log
from flightctl.params import load
from flightctl.sim.causes import CAUSES
from flightctl.sim.causes.rotor_drag import N_NUISANCE
from flightctl.sim.diagnose.basemodel import equivalent
from flightctl.sim.diagnose.candidate import COARSE_STRIDE
from flightctl.sim.diagnose.data import FOREIGN_COLUMNS, load_file
from flightctl.sim.diagnose.dataset import N_BLOCKS, DataSet, Vehicle
from flightctl.sim.diagnose.scoring import linear_stats, solve
from helpers.real import FLIGHTS, need


@pytest.fixture(scope="module")
def ds(tmp_path_factory):
    """LOG00037 (17 s at 1 kHz, a 6S five-inch-class quad's punch-outs) as an identified vehicle's data set."""
    csv = tmp_path_factory.mktemp("grid") / "LOG00037.csv"
    assert main(["log", "import", str(need(FLIGHTS / "betaflight" / "LOG00037.BFL")), str(csv), "--quiet"]) == 0
    f = load_file(read_flight_log(str(csv), extra=FOREIGN_COLUMNS), load(None).airframe)
    return DataSet([f], Vehicle(equivalent(0.0), f.layout, (0.0, 0.0, 0.0), identified=True))


def exhaustive(cand) -> tuple[list[float], int]:
    """(each fold's best grid point, the full data's best index) over every point of the grid."""
    ds = cand.ds
    stats = [linear_stats(ds, *cand.design(th)) for th in cand.grid]
    blocks = np.arange(N_BLOCKS)
    folds = [float(cand.grid[int(np.argmin([solve(st, blocks != b, ds.block_counts)[0] for st in stats]))])
             for b in blocks]
    return folds, int(np.argmin([solve(st, np.ones(N_BLOCKS, bool), ds.block_counts)[0] for st in stats]))


@pytest.mark.parametrize("cause", ["motor_lag", "actuation_delay", "gyro_lag"])
def test_the_walk_from_the_coarse_grid_finds_what_the_whole_grid_finds(ds, cause):
    fresh = copy.copy(ds)
    fresh.changes = {}
    cand = CAUSES[cause].candidate(fresh)
    assert len(cand.grid) > 3 * COARSE_STRIDE
    folds, best = exhaustive(cand)
    got = CAUSES[cause].candidate(fresh).run()
    assert got.folds == folds
    assert got.parameters == {cand.name: round(cand._best(best), cand.round_to)}


def test_a_kept_change_is_the_computed_one_and_follows_the_model(ds):
    base = copy.copy(ds)
    base.changes = {}
    first = CAUSES["motor_lag"].candidate(base).run()
    kept = {k for k in base.changes if k[0] == "motor_lag"}
    assert kept and not any(k[0] == "gyro_lag" for k in base.changes)   # gyro_lag's change has the carried terms in it
    # a copy that carries one more term (a drawn smooth wrench on the gyro channels): the same model, the same store
    rng = np.random.default_rng(35)
    carried = copy.copy(base)
    carried.carried, carried.carried_parameters = dict(base.carried), dict(base.carried_parameters)
    term = np.zeros_like(base.r_base)
    term[:3] = np.cumsum(rng.standard_normal((3, base.n)), axis=1) * rng.uniform(0.01, 0.1)
    carried.carry("a drawn term", {}, term)
    assert carried.changes is base.changes
    with_store = CAUSES["motor_lag"].candidate(carried).run()
    anew = copy.copy(carried)
    anew.changes = {}
    without = CAUSES["motor_lag"].candidate(anew).run()
    assert with_store.parameters == without.parameters and with_store.folds == without.folds
    np.testing.assert_array_equal(with_store.score.rss, without.score.rss)
    np.testing.assert_array_equal(with_store.residual, without.residual)
    assert with_store.score.rss.sum() != first.score.rss.sum()         # the carried term did change the fit
    # a model whose thrusts changed (an actuation delay folded in) gets a store of its own
    folded = copy.copy(base)
    CAUSES["actuation_delay"].candidate(folded).fold({"delay": 0.01})
    assert folded.changes is not base.changes and not folded.changes


def test_rotor_drags_change_is_the_files_alone_and_kept_across_models(ds):
    rng = np.random.default_rng(48)
    base = copy.copy(ds)
    base.of_files = {}
    cand = CAUSES["rotor_drag"].candidate(base)
    k = float(rng.choice(cand.grid[1:]))
    ch = cand.change(k)
    assert list(base.of_files) == [("rotor_drag", k)]
    # the drag and its nuisances filtered side by side: row for row what each input filtered alone gives
    alone = [base.flat_filtered(cand._filtered(k, [x[j] for x in cand._inputs()])) for j in range(1 + N_NUISANCE)]
    np.testing.assert_array_equal(ch.delta, alone[0])
    np.testing.assert_array_equal(ch.free[:N_NUISANCE], np.stack(alone[1:]))
    between = float(np.sqrt(k * cand.grid[list(cand.grid).index(k) + 1]))    # a refinement's drag: not kept
    cand.change(between)
    assert ("rotor_drag", between) not in base.of_files
    # a gyro lag folded in: a new model, the same store, and what the store holds is what that model computes
    lagged = copy.copy(base)
    CAUSES["gyro_lag"].candidate(lagged).fold({"tau": float(rng.uniform(0.005, 0.03))})
    assert lagged.changes is not base.changes and lagged.of_files is base.of_files
    kept = CAUSES["rotor_drag"].candidate(lagged).change(k)
    fresh = copy.copy(lagged)
    fresh.of_files = {}
    anew = CAUSES["rotor_drag"].candidate(fresh).change(k)
    np.testing.assert_array_equal(kept.delta, anew.delta)
    np.testing.assert_array_equal(kept.free, anew.free)
    assert not np.array_equal(kept.free[N_NUISANCE:], ch.free[N_NUISANCE:])   # the model's own columns did change
