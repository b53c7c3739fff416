"""A digital filter run one sample at a time, as a firmware runs it: the reference the frequency-domain
loops are checked against (tests/sim/diagnose/test_predict.py, test_loops.py, tests/sim/sweeps/test_fromlog.py)."""
import numpy as np


class DirectForm:
    """A direct-form filter of (b, a), one sample at a time."""
    def __init__(self, stages):
        self.stages = [(np.array(b, float), np.array(a, float), np.zeros(len(b)), np.zeros(len(a))) for b, a in stages]

    def __call__(self, x):
        for b, a, xs, ys in self.stages:
            xs[1:] = xs[:-1]
            xs[0] = x
            y = (b @ xs - a[1:] @ ys[:-1]) / a[0]
            ys[1:] = ys[:-1]
            ys[0] = y
            x = y
        return x
