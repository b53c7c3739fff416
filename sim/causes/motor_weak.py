"""`motor_weak(motor, scale)`: one motor gives a fraction of its modelled thrust and torque."""
from __future__ import annotations

import numpy as np

from flightctl.errors import InputError
from flightctl.sim.identify.diagnose.candidate import AffineCandidate, Result
from flightctl.sim.identify.diagnose.scoring import heldout, objective
from flightctl.sim.model import Effect, Parameter


class MotorWeak(Effect):
    """One motor gives a fraction `scale` of its modelled thrust and torque."""
    cause, uses_scale = "motor_weak", True
    required = {"motor": Parameter("1-4", 1, 4), "scale": Parameter("1", 0.0, 2.0)}

    def __init__(self, **parameters):
        super().__init__(**parameters)
        if self.parameters["motor"] != int(self.parameters["motor"]):
            raise InputError("motor_weak: motor must be 1, 2, 3 or 4")
        self._i = int(self.parameters["motor"]) - 1

    def scale(self, t, x, u, s):
        s[self._i] *= self.parameters["scale"]


class MotorWeakFit(AffineCandidate):
    """Rotor m's thrust and torque times `scale`: D = (scale - 1) G_m. Each fold picks the motor
    whose fit is best on its training blocks."""
    effect = MotorWeak
    explains = "thrust of the weak motor (N)"

    def _column(self, m):
        ds = self.ds
        return ds.flat_filtered([ds.thrust_columns(i)[m] for i in range(len(ds.files))])

    def predict(self, parameters):
        return (parameters["scale"] - 1.0) * self._column(int(parameters["motor"]) - 1)

    def run(self):
        ds = self.ds
        Gm = [self._column(m) for m in range(4)]
        folds = []

        def best(train):
            out = []
            for m in range(4):
                th = self.fit(None, [Gm[m]], train)
                out.append((objective(self.residual_at(None, [Gm[m]], th), train), m, float(th[0])))
            return min(out)

        def fold(train):
            _, m, th = best(train)
            folds.append({"motor": m + 1, "scale": 1.0 + th})
            return self.residual_at(None, [Gm[m]], [th])

        score = heldout(ds, fold)
        _, m, th = best(np.ones(ds.n, bool))
        self._m = m
        return Result(self.cause, {"motor": m + 1, "scale": round(1.0 + th, 4)}, score,
                      self.residual_at(None, [Gm[m]], [th]), explains=self.explains, folds=folds)

    def explanatory(self):
        return self.ds.thrust[getattr(self, "_m", 0)]
