"""Short flights that excite what `flightctl diagnose` needs to see (docs/diagnose.md).

`excite` (44 s after arming): a low hover at 0.25 m (ground effect), a climb, roll and pitch steps
of +-4 degrees (horizontal speed: rotor drag; sharp command edges: lag against delay), yaw steps of
+-60 degrees (yaw rates of 2-3 rad/s: linear yaw drag), a climb to 2 m and a slow descent back to
0.25 m and to the floor (thrust changes: battery sag, ground effect again).
"""
from __future__ import annotations

from flightctl.plan import Move, Plan
from flightctl.sim.scenarios import Scenario, _angle_steps


def excite() -> Scenario:
    r_moves, r_steps = _angle_steps("roll", [(10, 4, 2), (12, -4, 2), (14, 0, 2)])
    p_moves, p_steps = _angle_steps("pitch", [(16, 4, 2), (18, -4, 2), (20, 0, 2)])
    y_moves, y_steps = _angle_steps("yaw", [(22, 60, 5), (27, -60, 5), (32, 0, 4)])
    moves = ([Move(0.0, "alt", 0.25, 2.0), Move(6.0, "alt", 1.2, 3.0)] + r_moves + p_moves + y_moves
             + [Move(35.0, "alt", 2.0, 2.0), Move(38.0, "alt", 0.25, 3.0), Move(42.0, "alt", 0.0, 1.5)])
    return Scenario("excite", Plan(moves, 44.0, "excite"), tuple(r_steps + p_steps + y_steps),
                    "low hover at 0.25 m, roll/pitch steps +-4 deg, yaw steps +-60 deg, climb to 2 m, "
                    "descend to 0.25 m, land")


def hover_low() -> Scenario:
    """Take off to 0.2 m, hold, climb to 1 m, come back down to 0.2 m and land: ground effect."""
    moves = [Move(0.0, "alt", 0.2, 2.0), Move(8.0, "alt", 1.0, 3.0), Move(14.0, "alt", 0.2, 3.0),
             Move(22.0, "alt", 0.0, 1.0)]
    return Scenario("hover_low", Plan(moves, 24.0, "hover_low"), (), "hover low (0.2 m), climb to 1 m, back, land")


SCENARIOS = {"excite": excite, "hover_low": hover_low}
