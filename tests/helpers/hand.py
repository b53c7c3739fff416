"""Values worked out by hand for the tests, independent of the code under test."""
import math

import numpy as np


def R_hand(phi, theta, psi):
    """R = Rz(psi) Ry(theta) Rx(phi), body to inertial (conventions.md), from the elementary rotations."""
    cf, sf, ct, st, cp, sp = (math.cos(phi), math.sin(phi), math.cos(theta), math.sin(theta),
                              math.cos(psi), math.sin(psi))
    Rx = np.array([[1, 0, 0], [0, cf, -sf], [0, sf, cf]])
    Ry = np.array([[ct, 0, st], [0, 1, 0], [-st, 0, ct]])
    Rz = np.array([[cp, -sp, 0], [sp, cp, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx
