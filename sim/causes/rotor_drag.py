"""`rotor_drag(k)`: a horizontal drag force on the body, -k (u, v) in the body frame.

The drag acts at each rotor (blade flapping and induced drag: the rotor's H-force, about k / 4 per
rotor for its own horizontal velocity). A yaw rate r moves each rotor sideways at r l, so the four
drags also make a yaw moment -4 (k / 4) l^2 r = -k l^2 r (0.10 N m s/rad at k = 1.70 N s/m, beside
Jzz = 0.029 kg m^2). That moment is the optional `yaw` (N m s/rad, default 0), not taken from k,
because a yaw drag identified on the spinning vehicle holds part of it already: the paper's rig
(eq. 6, section 3.2) spun the quadcopter on rotors 1 and 3 with 2 and 4 off, so its gamma1 r^2
includes the edgewise drag of the two running rotors; in flight, 2 and 4 add theirs, (k / 2) l^2
(scripts/as_flown.py). The fit below predicts the accelerometer's x and y and reports k only.

Both terms come from the air the rotors move. The force is momentum theory's ram drag: a rotor
turns the free stream's horizontal momentum at its mass flow rho A v_i, and its induced velocity v_i
is v_h sqrt(f_i / B) (v_i = sqrt(f_i / (2 rho A)): Leishman, *Principles of Helicopter
Aerodynamics*, ch. 2), so each rotor's drag is k / 4 times its `rotor_inflow.airflow_root`
sqrt(f_i / B), and the force is k times their sum over 4: k at hover, and on one pair carrying the
weight (2 B each: a lost motor and the one across it stopped, flightctl/control/spin.py) 2 sqrt(2) / 4
= 0.71 k, not half of it. `yaw` holds the rotors beyond the two whose share eq. 6's gamma1 holds
already (`rotor_inflow.airflow`, the summed shares s, 4 for four rotors carrying thrust), so it is
yaw (s - 2) / 2, none below two: on one pair the yaw drag is eq. 6's alone, as on the rig.
"""
from __future__ import annotations

import math

import numpy as np

from flightctl.sim.causes.rotor_inflow import airflow, airflow_root
from flightctl.sim.diagnose.candidate import GridCandidate, Result
from flightctl.sim.diagnose.data import stretches
from flightctl.sim.diagnose.dataset import C, N_BLOCKS, Change
from flightctl.sim.diagnose.scoring import linear_stats, solve
from flightctl.sim.world.model import R, Effect, Parameter


def drag_wrench(k: float, yaw: float, running, flow, u, v, r):
    """The body-frame drag force -k (u, v) flow / 4 and the rotors' yaw damping -yaw r: `flow` the
    rotors' summed `airflow_root`s (momentum theory's ram drag, 4 at hover), `running` their summed
    shares (`airflow`: 4 for four rotors carrying thrust, 2 for one pair)."""
    kr = 0.25 * k * flow
    beyond = 0.5 * (running - 2.0 + abs(running - 2.0))      # max(running - 2, 0): beyond gamma1's pair
    return -kr * u, -kr * v, -0.5 * yaw * beyond * r


class RotorDrag(Effect):
    """Horizontal drag on the body, -k (u, v) in the body frame (blade flapping and induced drag).

    Optional `yaw`: the rotors' drags about z_b, -yaw r (the module docstring)."""
    cause, uses_wrench = "rotor_drag", True
    required = {"k": Parameter("N s/m", 0.0, 20.0)}
    optional = {"yaw": Parameter("N m s/rad", 0.0, 10.0)}
    compiled, compiled_hook = True, "drag"

    def compiled_q(self):
        return {"k_drag": self.parameters["k"], "yaw": self.parameters.get("yaw", 0.0)}

    def attach(self, airframe, offset):
        super().attach(airframe, offset)
        self._B = airframe.M * airframe.g / 4.0

    def wrench(self, t, x, f, vb, force, torque):
        B = self._B
        r1, r2, r3, r4 = airflow_root(f[0], B), airflow_root(f[1], B), airflow_root(f[2], B), airflow_root(f[3], B)
        fx, fy, tz = drag_wrench(self.parameters["k"], self.parameters.get("yaw", 0.0), airflow(r1, r2, r3, r4),
                                 r1 + r2 + r3 + r4, vb[0], vb[1], x[R])
        force[0] += fx
        force[1] += fy
        torque[2] += tz   # each rotor's drag at r l, arm l


# Rotor drag per unit mass, k / M (1/s): measured quadrotors give 0.3-0.6 (docs/as-flown.md, the as-flown
# model's review); momentum theory's ram drag, an upper estimate, is g / (2 v_h), 1.03 1/s for the paper's
# vehicle (Table 2's mass on 12-inch rotors, v_h = 4.75 m/s: scripts/as_flown.py). A vehicle whose rotors
# are half as loaded has v_h 1/sqrt(2) of it: twice the paper's ram drag bounds the physical range.
MAX_K_OVER_M = 2.0
# And below: a rotor making thrust in edgewise flow tilts it back (momentum theory's ram drag), so no
# quadrotor flies without rotor drag; a tenth of the smallest measured (0.3 1/s) bounds it from below. A
# refit that lands under it explains the accelerometer with the fit's nuisance biases, not with drag.
MIN_K_OVER_M = 0.03


N_NUISANCE = 4    # RotorDragFit's: the inertial biases along x and y, the gyro offsets on x_b and y_b
ACC_XY = slice(3, 5)    # the channels the drag acts on: acc_x, acc_y


def gyro_drift(f) -> list[np.ndarray]:
    """The inertial horizontal acceleration (2, n) that a unit offset of the gyro on x_b, then on y_b,
    leaks into R (0, 0, a_z) of file `f`. `data._rotations` integrates the gyro from the first motor
    start, R_(k+1) = R_k exp([w_k dt_k]x); an offset b on w tilts it to (I + [e_k]x) R_k with
    e_(k+1) = e_k + R_k b dt_k (first order), so that R (0, 0, a_z) is off by e_k x R_k e_z a_z.
    A gyro offset on z_b turns R about (nearly) the vertical, which leaks no horizontal
    acceleration: not a nuisance here. What the calibration leaves on the gyro (the still average's
    noise, the warm-up and in-run drift of sim/world/devices.py's `SensorNoise`) is small and matters
    all the same: 0.02 deg/s, 0.35 mrad/s, tilts R by 0.9 degrees in 45 s, 0.15 m/s^2 by then, the
    drag of 1.5 m/s at k / M = 0.1 1/s; taken for drag, that growing error lowered k by 40 % on a 48 s
    `excite` plan that lands (issue 49)."""
    Rm, acc_z = f.Rm, f.acc[2]
    start = int(np.argmax(f.running)) if f.running.any() else f.t.size
    dt = np.diff(f.t, append=f.t[-1])
    dt[:start] = 0.0
    out = []
    for j in (0, 1):                      # R's column j: the offset on x_b, on y_b, in the inertial frame
        e = [np.concatenate([[0.0], np.cumsum(Rm[3 * r + j] * dt)[:-1]]) for r in range(3)]
        out.append(np.vstack([acc_z * (e[1] * Rm[8] - e[2] * Rm[5]), acc_z * (e[2] * Rm[2] - e[0] * Rm[8])]))
    return out


class RotorDragFit(GridCandidate):
    """Horizontal drag -k (u, v) in the body frame. The body velocity is not logged; it is
    reconstructed by the model itself: the horizontal inertial acceleration is the horizontal part
    of R (0, 0, a_z) (a_z the measured specific force along z_b, R the integrated gyro) minus
    k v / M, so the horizontal velocity is that acceleration through a first-order filter with pole
    k / M, started at rest at take-off (small-tilt approximation for the drag direction). Its
    body-frame (u, v) gives the predicted accelerometer x, y: -k (u, v) / M. The initial tilt is
    known only to the accelerometer's bias, which leaks g times the tilt error into the horizontal
    acceleration as an unknown constant in the inertial frame: two nuisance parameters (b_x, b_y).
    And the integrated gyro drifts: the offset the calibration left on the roll and pitch gyros
    (`gyro_drift`) tilts R by a growing error, which leaks a growing horizontal acceleration: two
    more (the two offsets). All four are free columns fitted with the offsets for each k on the
    training blocks."""
    needs_accelerometer = True   # it predicts acc_x and acc_y only
    effect = RotorDrag
    explains = "reconstructed body velocity u (m/s)"
    physical_check = (f"k / M from {MIN_K_OVER_M:g} to {MAX_K_OVER_M:g} 1/s: measured quadrotors 0.3-0.6 1/s, momentum theory's ram "
                      "drag g / (2 v_h) 1.03 1/s for the paper's vehicle, an upper estimate (docs/as-flown.md)")
    grid = np.concatenate([[0.0], np.geomspace(0.01, 3.0, 36)])
    _grid = frozenset(float(k) for k in grid)
    round_to = 3

    def _filtered(self, k, inputs):
        """Per file: the (..., C, n) response -k/M R^T LPF_k(x) on acc_x, acc_y of inertial horizontal
        accelerations x (..., 2, n): all of them in one filter pass per stretch."""
        from scipy import signal   # here, not at the top: `flightctl sim` imports the causes for their effects
        ds, M = self.ds, self.ds.a.M
        out = []
        for f, x in zip(ds.files, inputs):
            v = np.zeros_like(x)
            a = math.exp(-k / M / ds.fs)
            g = (1.0 - a) * M / k if k > 0 else 1.0 / ds.fs
            for s0, s1 in stretches(f.running):
                v[..., s0:s1] = signal.lfilter([0.0, g], [1.0, -a], x[..., s0:s1], axis=-1)
            u = f.Rm[0] * v[..., 0, :] + f.Rm[3] * v[..., 1, :]     # R^T v, body x (horizontal v)
            w = f.Rm[1] * v[..., 0, :] + f.Rm[4] * v[..., 1, :]     # body y
            d = np.zeros(x.shape[:-2] + (C, x.shape[-1]))
            d[..., ACC_XY, :-1] = -k / M * np.stack([u, w], axis=-2)[..., 1:]     # the accelerometer row k + 1
            out.append(d)
        return out

    def _inputs(self) -> list[np.ndarray]:
        """Per file the (1 + N_NUISANCE, 2, n) inertial horizontal accelerations the fit filters: the
        measured one, R (0, 0, a_z), then what each nuisance leaks at unit size: the constant biases
        along x and y, the gyro offsets on x_b and y_b (`gyro_drift`). They do not depend on k:
        computed once, and filtered together at each k (one pass over the log, not five)."""
        if getattr(self, "_stacked", None) is None:
            self._stacked = []
            for f in self.ds.files:
                ones, zero = np.ones(f.t.size), np.zeros(f.t.size)
                self._stacked.append(np.stack([np.vstack([f.Rm[2] * f.acc[2], f.Rm[5] * f.acc[2]]),
                                               np.vstack([ones, zero]), np.vstack([zero, ones]), *gyro_drift(f)]))
        return self._stacked

    def change(self, k, keep: bool | None = None) -> Change:
        """The drag prediction at k, and as own free columns the responses to the nuisances (unit
        inertial biases, unit gyro offsets; zero at k = 0: no drag, no velocity to reconstruct).
        Both are the files' and the accelerometer's sensing alone, not the model's: kept in the data
        set's store (`DataSet.of_files`) at the grid's points and a carried term's k (`keep`), where
        every later round, the backfit and each gyro lag tried (which predicts the carried terms
        again) find them (docs/diagnose.md, "Speed")."""
        ds = self.ds
        if k <= 0:
            return Change(np.zeros((C, ds.n)), np.concatenate([np.zeros((N_NUISANCE, C, ds.n)), ds.base_free]))
        key = (self.cause, float(k))
        acc = ds.of_files.get(key)
        if acc is None:
            acc = ds.flat_filtered(self._filtered(k, self._inputs()))[:, ACC_XY]     # the other rows are zero
            if (float(k) in self._grid if keep is None else keep):
                ds.of_files[key] = acc
        both = np.zeros((1 + N_NUISANCE, C, ds.n))
        both[:, ACC_XY] = acc
        return Change(both[0], np.concatenate([both[1:], ds.base_free]))

    def predict(self, parameters):
        """The drag prediction at k with its nuisances fitted on all data (as the climb speed of
        `rotor_inflow` fits its initial height and speed): a carried effect's term."""
        k = float(parameters["k"])
        ch = self.change(k, keep=True)
        e = self.r_base - ch.delta
        A = np.stack(list(ch.free[:N_NUISANCE]), axis=-1)
        b = solve(linear_stats(self.ds, e, A), np.ones(N_BLOCKS, bool), self.ds.block_counts)[1]
        return ch.delta + A @ b

    def run(self) -> Result:
        result = super().run()
        self._k = result.parameters["k"]
        return result

    def not_named(self, result):
        if result.parameters["k"] <= 0:   # the folds chose some drag, the whole flight none: the held-out
            return ("rotor_drag: the fit on all the data finds no drag (k = 0); the held-out gain is its "
                    "nuisance biases': not named")    # gain came from the biases riding on the folds' k
        return None

    def physical(self, result):
        k_m = result.parameters["k"] / self.ds.a.M
        if k_m > MAX_K_OVER_M:
            return (f"k / M = {k_m:.2f} 1/s is above {MAX_K_OVER_M:g} 1/s, twice the ram drag of momentum theory for "
                    "the paper's vehicle (measured quadrotors: 0.3-0.6 1/s)")
        if 0.0 < k_m < MIN_K_OVER_M:
            return (f"k / M = {k_m:.3f} 1/s is below {MIN_K_OVER_M:g} 1/s, a tenth of the smallest measured on "
                    "quadrotors (0.3-0.6 1/s): a drag this small is the fit's nuisance biases, not the rotors'")
        return None

    def explanatory(self):
        k = max(getattr(self, "_k", 0.0), 1e-3)
        ds = self.ds
        d = self._filtered(k, [x[0] for x in self._inputs()])
        return ds.flat([x[3] * (-ds.a.M / k) for x in d])
