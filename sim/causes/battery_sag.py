"""`battery_sag(v_nominal)`: the thrust scales with the square of the battery voltage."""
from __future__ import annotations

import math

import numpy as np

from flightctl.battery import CELL_V
from flightctl.sim.diagnose.candidate import AffineCandidate
from flightctl.sim.world.model import Effect, Parameter

SAG_MIN_SPAN = 0.01      # battery_sag needs the voltage to vary by 1 % (5th to 95th percentile)
PACK_PERCENTILES = (0.5, 99.5)   # the pack's measured range: every logged voltage but single-sample dropouts


class BatterySag(Effect):
    """Thrust scales with (battery_v / v_nominal)^2: the propeller was identified at v_nominal."""
    cause, uses_scale = "battery_sag", True
    required = {"v_nominal": Parameter("V", 1.0, 60.0)}

    def scale(self, t, x, u, s):
        k = (u[4] / self.parameters["v_nominal"]) ** 2
        for i in range(4):
            s[i] *= k


def pack_range(files) -> tuple[float, float] | None:
    """(lowest, highest) battery voltage the logs measured (PACK_PERCENTILES of every logged row), or
    None without any."""
    V = np.concatenate([f.battery_v[np.isfinite(f.battery_v)] for f in files])
    if V.size == 0:
        return None
    lo, hi = np.percentile(V, PACK_PERCENTILES)
    return float(lo), float(hi)


class BatterySagFit(AffineCandidate):
    """Thrust times (V / v_nominal)^2: D = (c V^2 - 1) G with G the thrust-proportional part of the
    prediction, affine in c = 1 / v_nominal^2."""
    effect = BatterySag
    changes_thrust = True
    explains = "battery voltage (V)"
    physical_check = (f"v_nominal a voltage of the pack: inside the range the log measured (a base model identified "
                      f"from the flight holds the thrust at the flight's own voltages) and, where the cell count is "
                      f"known (`# battery_cells:`), within cells x {CELL_V[0]:g}-{CELL_V[1]:g} V (a lithium-polymer "
                      f"cell, discharged to charged, LiHV included); for this project's airframe, whose propeller "
                      f"was identified on the bench, the cells' range alone (cells from the log, else the fewest "
                      f"whose {CELL_V[1]:g} V reach the highest voltage logged)")

    def why_not(self):
        V = self.ds.V
        if not np.isfinite(V).all():
            return "battery_v is missing in flight"
        lo, hi = np.percentile(V, [5, 95])
        span = (hi - lo) / np.median(V)
        if span < SAG_MIN_SPAN:
            return (f"battery_v hardly varies in flight ({100 * span:.2f} % from the 5th to the 95th "
                    f"percentile, {100 * SAG_MIN_SPAN:g} % needed): a constant voltage only rescales the thrust")
        return None

    def columns(self):
        ds = self.ds
        G = [ds.thrust_columns(i).sum(axis=0) for i in range(len(ds.files))]
        G0 = -ds.flat_filtered(G)
        G1 = ds.flat_filtered([g * f.battery_v ** 2 for g, f in zip(G, ds.files)])
        return G0, [G1]

    def scales(self, parameters):
        return [(f.battery_v / parameters["v_nominal"]) ** 2 for f in self.ds.files]

    def why_not_carried(self):
        return None if np.isfinite(self.ds.V).all() else "battery_v is missing in flight"

    def from_parameters(self, parameters):
        return [1.0 / parameters["v_nominal"] ** 2]

    def to_parameters(self, theta):
        c = float(theta[0])
        return {"v_nominal": round(1.0 / math.sqrt(c), 3) if c > 0 else None}

    def not_named(self, result):
        if result.parameters.get("v_nominal") is None:
            return "battery_sag: the fit wants no voltage dependence (1/v_nominal^2 <= 0): not named"
        return None

    def physical(self, result):
        v = result.parameters.get("v_nominal")
        if v is None:
            return None
        lo, hi = self.pack_range()
        cells = self.cells()
        where = []
        if self.ds.vehicle.identified and not lo <= v <= hi:
            where.append(f"outside the {lo:.1f}-{hi:.1f} V this pack showed in the log")
        if cells is not None:
            c_lo, c_hi = cells[0] * CELL_V[0], cells[0] * CELL_V[1]
            if not c_lo <= v <= c_hi:
                where.append(f"outside the {c_lo:.1f}-{c_hi:.1f} V of a {cells[0]}-cell pack ({cells[1]})")
        if where:
            return f"v_nominal {v:.1f} V is " + " and ".join(where)
        return None

    def pack_range(self) -> tuple[float, float]:
        return pack_range(self.ds.files)

    def cells(self) -> tuple[int, str] | None:
        """(cell count, where it comes from): the logs' `# battery_cells:`, else for this project's
        airframe the fewest cells whose full charge reaches the highest voltage logged; None for an
        identified vehicle without it (its measured range is the check)."""
        declared = {f.battery_cells for f in self.ds.files if f.battery_cells}
        if declared:
            return max(declared), "the log's battery_cells"
        if self.ds.vehicle.identified:
            return None
        return max(1, math.ceil(self.pack_range()[1] / CELL_V[1])), "the highest voltage logged"

    def explanatory(self):
        return self.ds.V
