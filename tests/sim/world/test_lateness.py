"""The loop's lateness flown (sim/world/lateness.py): a late tick acts late on the plant, the loop's own
overrun count sees every late tick, and a clock with no late tick flies the lock-step flight bit for bit.
The late-loop distribution is drawn at random here from a seeded generator; the clock is told only it."""
from __future__ import annotations

import numpy as np
import pytest

from flightctl.boards import BoardOptions
from flightctl.control.controller import FlightController
from flightctl.errors import InputError
from flightctl.loop import FlightLoop
from flightctl.plans.plan import Move, Plan
from flightctl.sim import causes
from flightctl.sim.world import faults, lateness
from flightctl.sim.world.board import SIM_CALIBRATE_S, open_board
from flightctl.sim.world.lateness import LateClock, Lateness

PARAMS = causes.load_vehicle("paper-as-flown")      # with its actuation delay (1.47 periods)
PERIOD = PARAMS.airframe.dt


def plan() -> Plan:
    """Take off to 1 m, bank 5 degrees and back, land: 9 s."""
    return Plan([Move(0.0, "alt", 1.0, 2.0), Move(3.0, "roll", 0.087, 0.0), Move(4.5, "roll", 0.0, 0.0),
                 Move(6.0, "alt", 0.0, 2.0)], 9.0, "late", "a bank in a hover")


def flown(clock=None, seed=3):
    """The flight on the sim board (its clock replaced by `clock(world)`): the loop's result, the
    plant's state at each tick, and at each tick whether the plant was inside a period (a late tick)."""
    board = open_board(PARAMS, BoardOptions(seed=seed))
    hal, world = board.hal, board.world
    if clock is not None:
        hal.clock = clock(world)
    states, inside = [], []

    def tick(i):
        states.append(tuple(world.plant.x))
        inside.append(world.plant.into > 0.0)
    result = FlightLoop(hal, PARAMS, plan(), None, FlightController(PARAMS), calibrate_s=SIM_CALIBRATE_S,
                        on_tick=tick).run()
    return result, states, inside


@pytest.fixture(scope="module")
def on_time():
    return flown()


def random_lateness(rng) -> Lateness:
    q = np.sort(rng.uniform(20e-6, rng.uniform(0.5, 3.0) * PERIOD, int(rng.integers(2, 40))))
    return Lateness("drawn", float(rng.uniform(0.005, 0.05)), tuple(q.tolist()), {})


def test_a_clock_with_no_late_tick_flies_the_lockstep_flight_bit_for_bit(on_time):
    never = Lateness("never", 0.0, (1e-4, 2e-3), {})
    result, states, inside = flown(lambda w: LateClock(w, never))
    assert states == on_time[1] and not any(inside)
    assert result.overruns == 0 == on_time[0].overruns and result.reason == on_time[0].reason == "plan complete"


@pytest.mark.parametrize("seed", [11, 12])
def test_the_loops_overrun_count_is_the_late_ticks_and_they_act_late(on_time, seed):
    rng = np.random.default_rng(seed)
    dist = random_lateness(rng)
    clock_seed = int(rng.integers(1 << 30))
    at = SIM_CALIBRATE_S + float(rng.uniform(0.5, 3.0))      # from a moment after arming
    result, states, inside = flown(lambda w: LateClock(w, dist, seed=clock_seed, at=at))
    late = sum(inside)              # ticks the loop ran inside a period: the plant had flown on to them
    assert late > 0
    assert result.overruns == late  # the loop's own statistic (FlightResult.overruns, as on the Pi)
    assert states != on_time[1][:len(states)]
    first = inside.index(True)      # the first late tick (the motors spinning): the same flight until it
    assert states[:first] == on_time[1][:first] and states[first] != on_time[1][first]
    assert first >= round(at / PERIOD) - 1
    assert result.reason == "plan complete"


def test_a_tick_late_by_whole_periods_skips_them_and_the_loop_names_the_stall():
    long = Lateness("long", 0.002, (2.5 * PERIOD, 3.5 * PERIOD), {})
    result, _, inside = flown(lambda w: LateClock(w, long, seed=5))
    stalls = [what for _, what in result.events if what.startswith("loop stalled")]
    assert result.overruns == sum(inside) > 0 and 0 < len(stalls) <= result.overruns
    assert all("3 ticks missed" in s or "2 ticks missed" in s for s in stalls), stalls


def test_the_fault_takes_a_shipped_distribution_and_refuses_others():
    for name in lateness.names():
        d = lateness.load(name)
        assert 0.0 < d.share < 1.0 and d.source
    f = faults.parse("loop_late:dist=busy,rate=10,seed=4,at=0")
    assert f.options == {"dist": "busy", "rate": 10.0, "seed": 4.0} and f.at == 0.0
    for bad in ("loop_late:dist=nowhere", "loop_late:rate=-1", "loop_late:speed=2"):
        with pytest.raises(InputError, match="--fault loop_late"):
            faults.parse(bad)


@pytest.mark.parametrize("delay_periods", [0.0, 0.4, 1.47])
def test_a_late_command_acts_its_lateness_after_an_on_time_one_would(delay_periods):
    """The plant's input over each period is the time-weighted mix of the commands active in it: a
    command issued a fraction `lam` into its period acts from `lam` plus the delay on (held before)."""
    from flightctl.sim.world.model import Model
    from flightctl.sim.world.plant import Plant
    a = PARAMS.airframe
    rng = np.random.default_rng(int(100 * delay_periods) + 1)
    model = Model(a, (causes.make("actuation_delay", delay=delay_periods * a.dt),) if delay_periods else ())
    plant = Plant(model, a.dt)
    plant.issue_times()
    old, new = tuple(rng.uniform(0, 1, 4)) + (16.0,), tuple(rng.uniform(0, 1, 4)) + (16.0,)
    for _ in range(3):
        plant.command(*old)
        plant.advance(a.dt)
    lam = float(rng.uniform(0.1, 0.9))
    plant.advance_part(lam)
    assert plant.u == pytest.approx(old)                 # the motors hold the last command up to the late tick
    plant.command(*new)
    starts = lam + delay_periods                         # where the new command acts, in periods from here
    seen = []
    while plant.periods < 10:
        a0 = plant.into
        plant.advance(a.dt)
        lo, hi = a0 + len(seen), 1.0 + len(seen)         # this segment, in periods from the late period's start
        share_new = min(max(hi - max(starts, lo), 0.0), hi - lo) / (hi - lo)
        seen.append((1.0 - share_new) * (hi - lo))     # the time the old command still held
        assert plant.u == pytest.approx(tuple(o + share_new * (n - o) for o, n in zip(old, new)), abs=1e-12)
        plant.command(*new)
    assert sum(seen) == pytest.approx(delay_periods)    # after the late tick, the old command held for the delay


def test_the_command_flies_the_late_loop_and_reports_its_overruns(tmp_path, capsys):
    import json

    from flightctl.cli import main
    out = tmp_path / "m.json"
    assert main(["sim", "hover", "--log", str(tmp_path / "f.csv"), "--fault", "loop_late:dist=busy,at=1",
                 "--json", str(out), "--quiet"]) == 0
    m = json.loads(out.read_text())
    assert m["overruns"] > 0 and m["stalls"] > 0 and m["outcome"] == "landed upright"
    assert main(["sim", "paper", "--params", "paper-as-flown", "--monte-carlo", "2", "--batch",
                 "--fault", "loop_late:dist=busy"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--fault" in err[0] and "--batch" in err[0]
