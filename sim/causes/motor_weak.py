"""`motor_weak(motor, scale)`: one motor gives a fraction of its modelled thrust and torque."""
from __future__ import annotations

import numpy as np

from flightctl.errors import InputError
from flightctl.sim.diagnose.candidate import AffineCandidate, Result, columns_of
from flightctl.sim.diagnose.dataset import N_BLOCKS, Change
from flightctl.sim.diagnose.scoring import fitted, heldout, linear_stats, solve
from flightctl.sim.world.model import Effect, Parameter


class MotorWeak(Effect):
    """One motor gives a fraction `scale` of its modelled thrust and torque."""
    cause, uses_scale = "motor_weak", True
    required = {"motor": Parameter("1-4", 1, 4), "scale": Parameter("1", 0.0, 2.0)}
    compiled = True     # a scale of one rotor: no wrench hook

    def compiled_q(self):
        return {"weak": self._i, "scale": self.parameters["scale"]}

    def __init__(self, **parameters):
        super().__init__(**parameters)
        if self.parameters["motor"] != int(self.parameters["motor"]):
            raise InputError("motor_weak: motor must be 1, 2, 3 or 4")
        self._i = int(self.parameters["motor"]) - 1

    def scale(self, t, x, u, s):
        s[self._i] *= self.parameters["scale"]


# A motor's thrust and torque against the model's: half to one and a half. A motor at half its siblings'
# thrust for the same command needs twice their command's thrust to hold the vehicle level: at a hover
# at 50 % of full thrust (thrust-to-weight 2) it is then at its limit; beyond, the fit stands for a
# wrong motor order or scaling (which the base model's checks catch) rather than a motor.
SCALE_RANGE = (0.5, 1.5)


class MotorWeakFit(AffineCandidate):
    """Rotor m's thrust and torque times `scale`. The change is linear in the scale but for the
    rotor's momentum of eq. 9 (its speed goes as the square root of the thrust), which a fit of the
    linear column G_m (`DataSet.thrust_columns`) leaves out: the fit is repeated on the secant
    column (D(s0) - D(1)) / (s0 - 1) through the exact change at the first fit's scale s0, so that
    the scale is exact there (a biased scale leaves a constant torque that `com_offset` would take
    up). Each fold picks the motor whose fit is best on its training blocks."""
    effect = MotorWeak
    changes_thrust = True
    explains = "thrust of the weak motor (N)"
    physical_check = (f"scale within {SCALE_RANGE[0]:g}-{SCALE_RANGE[1]:g} (a motor at half its siblings' thrust holds a "
                      "vehicle hovering at half its full thrust only at its limit); where the log has rotor speeds, "
                      "the motor turns slower for its command than the others (rotor_gain_check)")

    def why_not(self):
        if self.ds.vehicle.identified:
            return ("each rotor's own gain is identified in the base model of this vehicle "
                    "(base_model.rotor_gain): a weak motor is one below 1 there")
        return None

    def _exact(self, m, scale):
        """The filtered change of the prediction with rotor m's thrust and torque times `scale`."""
        ds = self.ds
        s = np.ones((4, 1))
        s[m] = scale
        return ds.delta_filtered([ds.predict_file(i, D, scale=s) for i, D in enumerate(ds.D)]).delta

    def predict(self, parameters):
        return self._exact(int(parameters["motor"]) - 1, parameters["scale"])

    def scales(self, parameters):
        s = np.ones((4, 1))
        s[int(parameters["motor"]) - 1] = parameters["scale"]
        return [s] * len(self.ds.files)

    def _fit(self, columns):
        """(designs, stats, best) of the single-column fits, one per motor."""
        ds = self.ds
        designs = [columns_of(Change(None, ds.base_free), [g]) for g in columns]
        stats = [linear_stats(ds, self.r_base, A) for A in designs]

        def best(keep):
            return min((solve(st, keep, ds.block_counts), m) for m, st in enumerate(stats))
        return designs, best

    def run(self):
        ds = self.ds
        e = self.r_base
        allb = np.ones(N_BLOCKS, bool)
        linear = [ds.flat_filtered([ds.thrust_columns(i)[m] for i in range(len(ds.files))]) for m in range(4)]
        designs, best = self._fit(linear)
        secant = []
        for m in range(4):
            s0 = 1.0 + float(solve(linear_stats(ds, e, designs[m]), allb, ds.block_counts)[1][0])
            secant.append(self._exact(m, s0) / (s0 - 1.0) if abs(s0 - 1.0) > 1e-6 else linear[m])
        designs, best = self._fit(secant)
        folds = []
        blocks = np.arange(N_BLOCKS)

        def fold(b):
            (_, th, off), m = best(blocks != b)
            folds.append({"motor": m + 1, "scale": 1.0 + float(th[0])})
            i0, i1 = ds.block_edges[b]
            return fitted(e[:, i0:i1], designs[m][:, i0:i1], th), off

        score = heldout(ds, fold)
        (_, th, _), m = best(allb)
        self._m = m
        return Result(self.cause, {"motor": m + 1, "scale": round(1.0 + float(th[0]), 4)}, score,
                      fitted(e, designs[m], th), explains=self.explains, folds=folds)

    def physical(self, result):
        from flightctl.sim.diagnose.rotorspeed import CURVE_TOL, GAIN_TOL   # it imports the causes
        m, s = int(result.parameters["motor"]), result.parameters["scale"]
        if not SCALE_RANGE[0] <= s <= SCALE_RANGE[1]:
            return f"motor {m} at {s:.2f} of its modelled thrust is outside {SCALE_RANGE[0]:g}-{SCALE_RANGE[1]:g}"
        speeds = self.ds.rotor_speeds
        if s < 1.0 - GAIN_TOL and speeds is not None and speeds.get("speed_gain") is not None:
            q = np.asarray(speeds["speed_gain"]) ** 2
            q = q / q.mean()
            if q[m - 1] >= 1.0 - CURVE_TOL:
                return (f"the log's rotor speeds put motor {m} on the others' speed-per-command curve (its speed gives "
                        f"{q[m - 1]:.3f} of the mean thrust): a weak motor turns slower for its command")
        return None

    def explanatory(self):
        return self.ds.thrust[getattr(self, "_m", 0)]
