"""`rotor_drag(k)`: a horizontal drag force on the body, -k (u, v) in the body frame."""
from __future__ import annotations

import math

import numpy as np

from flightctl.sim.identify.diagnose.candidate import Candidate, Result
from flightctl.sim.identify.diagnose.data import motors_on, stretches
from flightctl.sim.identify.diagnose.dataset import N_BLOCKS
from flightctl.sim.identify.diagnose.scoring import heldout
from flightctl.sim.model import Effect, Parameter


class RotorDrag(Effect):
    """Horizontal drag on the body, -k (u, v) in the body frame (blade flapping and induced drag)."""
    cause, uses_wrench = "rotor_drag", True
    required = {"k": Parameter("N s/m", 0.0, 20.0)}

    def wrench(self, t, x, f, vb, force, torque):
        k = self.parameters["k"]
        force[0] -= k * vb[0]
        force[1] -= k * vb[1]


class RotorDragFit(Candidate):
    """Horizontal drag -k (u, v) in the body frame. The body velocity is not logged; it is
    reconstructed by the model itself: the horizontal inertial acceleration is the horizontal part
    of R (0, 0, a_z) (a_z the measured specific force along z_b, R the integrated gyro) minus
    k v / M, so the horizontal velocity is that acceleration through a first-order filter with pole
    k / M, started at rest at take-off (small-tilt approximation for the drag direction). Its
    body-frame (u, v) gives the predicted accelerometer x, y: -k (u, v) / M. The initial tilt is
    known only to the accelerometer's bias, which leaks g times the tilt error into the horizontal
    acceleration as an unknown constant in the inertial frame: two nuisance parameters (b_x, b_y),
    fitted with the offsets by least squares for each k on the training blocks."""
    effect = RotorDrag
    explains = "reconstructed body velocity u (m/s)"
    grid = np.concatenate([[0.0], np.geomspace(0.01, 3.0, 36)])

    def _filtered(self, k, inputs):
        """Per file: the body-frame (2, n) response -k/M R^T LPF_k(x) of inertial horizontal x (2, n)."""
        from scipy import signal   # here, not at the top: `flightctl sim` imports the causes for their effects
        ds, M = self.ds, self.ds.a.M
        out = []
        for f, x in zip(ds.files, inputs):
            v = np.zeros_like(x)
            flying = motors_on(f.P, ds.a)
            a = math.exp(-k / M / ds.fs)
            g = (1.0 - a) * M / k if k > 0 else 1.0 / ds.fs
            for s0, s1 in stretches(flying):
                v[:, s0:s1] = signal.lfilter([0.0, g], [1.0, -a], x[:, s0:s1], axis=1)
            u = f.Rm[0] * v[0] + f.Rm[3] * v[1]     # R^T v, body x (horizontal v)
            w = f.Rm[1] * v[0] + f.Rm[4] * v[1]     # body y
            d = np.zeros((2, x.shape[1]))
            d[:, :-1] = -k / M * np.vstack([u, w])[:, 1:]     # the accelerometer row k + 1
            out.append(d)
        return out

    def columns(self, k):
        """Filtered (3, 2, n): the drag prediction and the responses to unit inertial biases."""
        ds = self.ds
        ah = [np.vstack([f.Rm[2] * f.acc[2], f.Rm[5] * f.acc[2]]) for f in ds.files]
        ones = [np.ones(f.t.size) for f in ds.files]
        zero = [np.zeros(f.t.size) for f in ds.files]
        cols = []
        for x in (ah, [np.vstack([o, z]) for o, z in zip(ones, zero)], [np.vstack([z, o]) for o, z in zip(ones, zero)]):
            cols.append(ds.flat_filtered(self._filtered(k, x)))
        return np.stack(cols)

    def _stats(self, cols):
        """Per block: sums and cross-products of e = r - drag prediction and the bias columns, x and y."""
        ds = self.ds
        e = self.r_base[3:5] - cols[0]
        A = np.stack([cols[1], cols[2]], axis=-1)          # (2, n, 2)
        st = []
        for i0, i1 in ds.block_edges:
            eb, Ab = e[:, i0:i1], A[:, i0:i1]
            st.append((eb.sum(axis=1), Ab.sum(axis=1), np.einsum("cn,cn->c", eb, eb),
                       np.einsum("cnp,cn->cp", Ab, eb), np.einsum("cnp,cnq->cpq", Ab, Ab)))
        return st

    @staticmethod
    def _solve(st, keep, n):
        """Weighted LSQ of the two inertial biases from the training blocks' statistics (offsets
        centred); returns (sum_c log RSS_c of x and y, b)."""
        se = sum(st[b][0] for b in keep)
        sA = sum(st[b][1] for b in keep)
        ee = sum(st[b][2] for b in keep) - se * se / n
        Ae = sum(st[b][3] for b in keep) - sA * se[:, None] / n
        AA = sum(st[b][4] for b in keep) - sA[:, :, None] * sA[:, None, :] / n
        w = 1.0 / np.maximum(ee, 1e-300)
        b = np.zeros(2)
        for _ in range(3):
            M = np.einsum("c,cpq->pq", w, AA)
            h = np.einsum("c,cp->p", w, Ae)
            b = np.linalg.lstsq(M + 1e-12 * np.trace(M) * np.eye(2), h, rcond=None)[0]
            rss = ee - 2.0 * Ae @ b + np.einsum("p,cpq,q->c", b, AA, b)
            w = 1.0 / np.maximum(rss, 1e-300)
        return float(np.log(np.maximum(rss, 1e-300)).sum()), b

    def _residual(self, cols, b):
        res = self.r_base.copy()
        res[3:5] = res[3:5] - cols[0] - b[0] * cols[1] - b[1] * cols[2]
        return res

    def predict(self, parameters):
        """The drag prediction at k with its two nuisance biases fitted on all data (as the climb
        speed of `rotor_inflow` fits its initial height and speed): a carried effect's term."""
        k = float(parameters["k"])
        out = np.zeros_like(self.r_base)
        if k > 0:
            cols = self.columns(k)
            b = self._solve(self._stats(cols), list(range(N_BLOCKS)), self.ds.n)[1]
            out[3:5] = cols[0] + b[0] * cols[1] + b[1] * cols[2]
        return out

    def run(self) -> Result:
        from scipy import optimize
        ds = self.ds
        counts = ds.block_counts
        zero = np.zeros((3, 2, ds.n))
        table = [self.columns(k) if k > 0 else zero for k in self.grid]
        stats = [self._stats(cols) for cols in table]

        def best(keep):
            n = counts[keep].sum()
            out = [self._solve(st, keep, n) for st in stats]
            j = int(np.argmin([o[0] for o in out]))
            return j, out[j][1]

        folds = []

        def fold(train):
            test_block = int(ds.block[~train][0])
            j, b = best([x for x in range(N_BLOCKS) if x != test_block])
            folds.append(float(self.grid[j]))
            return self._residual(table[j], b)

        score = heldout(ds, fold)
        allb = list(range(N_BLOCKS))
        j, b = best(allb)
        k = float(self.grid[j])
        if 0 < j < len(self.grid) - 1:     # refine between the neighbours
            lo, hi = self.grid[j - 1], self.grid[j + 1]
            opt = optimize.minimize_scalar(lambda kk: self._solve(self._stats(self.columns(kk)), allb, ds.n)[0],
                                           bounds=(lo, hi), method="bounded", options={"xatol": 1e-3})
            k = float(opt.x)
        cols = self.columns(k) if k > 0 else zero
        b = self._solve(self._stats(cols), allb, ds.n)[1]
        self._k = k
        return Result(self.cause, {"k": round(k, 3)}, score, self._residual(cols, b), explains=self.explains,
                      folds=folds)

    def explanatory(self):
        k = max(getattr(self, "_k", 0.0), 1e-3)
        ds = self.ds
        ah = [np.vstack([f.Rm[2] * f.acc[2], f.Rm[5] * f.acc[2]]) for f in ds.files]
        d = self._filtered(k, ah)
        return ds.flat([x[0] * (-ds.a.M / k) for x in d])
