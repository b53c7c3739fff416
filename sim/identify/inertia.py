"""Moments of inertia of section 3.2.2.

- Body (pendulum): per trial `J_P = M g r (T / 2 pi)^2` (eq. 17) and `J_C = J_P - M r^2` (eq. 18),
  averaged over the trials of each axis; stderr = std of the trials / sqrt(n).
- Rotor: per rotor `Jp = 1/2 m_b r_b^2 + 1/2 m_m r_m^2` (eq. 19-21; blade as a disc, motor as a solid
  cylinder), averaged over the rotors as the paper does; stderr = std of the rotors / sqrt(n).
"""
from __future__ import annotations

import numpy as np

from flightctl.sim.identify.fits import Identified, require, whole_numbers, within

AXES = {"x": "Jxx", "y": "Jyy", "z": "Jzz"}
ROTOR_COLUMNS = ("rotor", "part", "mass", "radius")
PARTS = ("blade", "motor")


def pendulum_inertia(M, g, r, T):
    """Eq. 17 and 18: inertia about the axis through the centre of mass, from one trial."""
    J_P = M * g * r * (T / (2 * np.pi)) ** 2
    return J_P - M * r ** 2


def disc_inertia(m, r):
    """Eq. 19 and 20: a uniform disc or solid cylinder about its axis."""
    return 0.5 * m * r ** 2


def _mean_with_error(groups: dict[str, np.ndarray]) -> tuple[dict, dict]:
    params = {k: {"value": float(v.mean()), "stderr": float(v.std(ddof=1) / np.sqrt(len(v)))} for k, v in groups.items()}
    rms = {k: float(v.std()) for k, v in groups.items()}  # of the trials about their mean
    return params, rms


def identify_pendulum(table, airframe) -> Identified:
    axis, r, T = table["axis"], table["pivot_distance"], table["period"]
    require(table, "axis", np.isin(axis, list(AXES)), "the axis must be x, y or z")
    require(table, "pivot_distance", r > 0, "the pivot distance must be positive")
    require(table, "period", T > 0, "the period must be positive")
    within(table, "pivot_distance", 0.0, 100.0, "m")
    within(table, "period", 0.0, 1e3, "s")
    M, g = airframe.M, airframe.g
    J = pendulum_inertia(M, g, r, T)
    require(table, "period", J > 0, "the period is shorter than a point mass at this pivot distance "
                                    "(eq. 18 gives a negative inertia)")
    groups = {}
    for a, name in AXES.items():
        k = axis == a
        if 0 < k.sum() < 2:
            table.fail(f"axis {a}: {k.sum()} trial, at least 2 needed to estimate the error", column="axis")
        if k.any():
            groups[name] = J[k]
    params, rms = _mean_with_error(groups)
    report = {"kind": "pendulum", "file": table.path, **params, "residual_rms": rms,
              "trials": {k: len(v) for k, v in groups.items()}, "M": M, "g": g}
    lines = [f"pendulum {table.path}: M = {M:g} kg, eq. 17-18 per trial, averaged per axis"]
    lines += [f"  {k} = {p['value']:.5g} ± {p['stderr']:.2g} kg m^2 ({len(groups[k])} trials)" for k, p in params.items()]
    return Identified(report, lines, {k: p["value"] for k, p in params.items()}, (groups, params))


def identify_rotor(table, airframe) -> Identified:
    rotor = whole_numbers(table, "rotor", 1, 4)
    part, m, r = table["part"], table["mass"], table["radius"]
    require(table, "part", np.isin(part, PARTS), "the part must be blade or motor")
    require(table, "mass", m > 0, "the mass must be positive")
    require(table, "radius", r > 0, "the radius must be positive")
    within(table, "mass", 0.0, 100.0, "kg")
    within(table, "radius", 0.0, 10.0, "m")
    J = disc_inertia(m, r)
    rotors = {}
    for i in map(int, np.unique(rotor)):
        k = rotor == i
        missing = [p for p in PARTS if not np.any(part[k] == p)]
        if missing:
            table.fail(f"rotor {i}: no {' and no '.join(missing)} row (eq. 21 adds blade and motor)", column="part")
        rotors[i] = {p: float(J[k & (part == p)].sum()) for p in PARTS}  # eq. 21
    if len(rotors) < 2:
        table.fail(f"{len(rotors)} rotor, at least 2 needed to average and estimate the error", column="rotor")
    Jp = np.array([sum(v.values()) for v in rotors.values()])
    params, rms = _mean_with_error({"Jp": Jp})
    report = {"kind": "rotor", "file": table.path, **params, "residual_rms": rms,
              "per_rotor": {str(i): {"Jp": sum(v.values()), **v} for i, v in rotors.items()}}
    lines = [f"rotor {table.path}: {len(rotors)} rotors, eq. 19-21, averaged",
             f"  Jp = {params['Jp']['value']:.4g} ± {params['Jp']['stderr']:.2g} kg m^2"]
    labels = [f"rotor {i}" for i in rotors]
    return Identified(report, lines, {"Jp": params["Jp"]["value"]}, ({"Jp": Jp}, params, labels))
