"""What a lithium-polymer pack's voltage can be: one definition for the loop's and the pre-arm's check
of each reading (flightctl/loop.py, flightctl/service) and the simulator's fits of a pack
(sim/causes/battery_sag.py, sim/diagnose/static/battery.py).

A reading outside what any pack of the vehicle's cell count can give is no reading of the pack: the
power monitor, its wiring or its bus is faulty (or the pack is not the one the vehicle was set up for),
and the low-battery check, fed with it, would be blind. It is refused before arming and lands the
vehicle in flight, named (docs/safety.md).
"""
from __future__ import annotations

CELLS = 4                # the vehicle's pack: 4S (the DJI E600 system's, sec. 3.1; the simulated pack's too)
LOW_CELL_V = 3.5         # V per cell: the loop lands below this (14.0 V on the 4S pack)
MIN_CELL_V = 3.6         # V per cell: refuse to arm below this (the default pre-arm threshold of every board)
FULL_CELL_V = 4.2        # V per cell: a LiPo cell charged full (its charger's end voltage)

# A lithium-polymer cell between fully discharged and fully charged at rest (a high-voltage cell, LiHV,
# to 4.35 V): the manufacturers' cut-off and charge voltages (Betaflight's vbat_min_cell_voltage 3.3 V
# default and vbat_max_cell_voltage 4.3 V bracket a pack's flying range inside it).
CELL_V = (3.0, 4.35)
# Under load a cell's terminal voltage sags below its 3.0 V cut-off at rest: 2.5 V per cell is the
# lowest discharge cut-off of lithium cells' datasheets, so a reading below it under any load is no
# cell's; none reads above a full LiHV cell.
READING_CELL_V = (2.5, CELL_V[1])


def implausible(volts: float, cells: int) -> str | None:
    """None when `volts` is a reading a pack of `cells` cells can give (READING_CELL_V per cell); else
    what is wrong with it (NaN: no reading at all)."""
    lo, hi = READING_CELL_V[0] * cells, READING_CELL_V[1] * cells
    if lo <= volts <= hi:
        return None
    if volts != volts:
        return "the power monitor gives no battery reading"
    return (f"battery reads {volts:.2f} V, outside what a {cells}S pack can give ({lo:.1f}-{hi:.1f} V): "
            "the power monitor or its wiring is faulty")
