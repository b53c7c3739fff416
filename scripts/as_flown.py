"""Derive the as-flown terms of the paper's vehicle from first principles and write the shipped
parameter file `flightctl/vehicles/paper-as-flown.toml` (`--params paper-as-flown`).

    python scripts/as_flown.py            # print the derivation and rewrite the file

Every number below carries its provenance; docs/as-flown.md explains the physics.
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

from flightctl.params import EffectSpec, Filters, Params, dumps

RHO = 1.225                 # kg/m^3, ISA sea level (the UIUC data's density)
BLADES = 2
CHORD_75 = 0.024            # m, chord at 0.75 R of a 12-inch two-blade multirotor propeller (DJI 1238 class)
LIFT_SLOPE = 5.7            # 1/rad, 2-D thin-aerofoil 2 pi less the usual 3-D/low-Reynolds loss
KV = 920.0                  # RPM/V: a ~900 KV 12-inch-class motor on 4S (hover near 40 % throttle)
R_PHASE = 0.10              # ohm, winding plus ESC of that motor class
J_BLADE_MODEL = 1.0e-4      # kg m^2, a 13 g two-blade 12-inch propeller as a rod (m R^2 / 3) plus the bell
J_RANGE = (0.8e-4, 2.66838e-4)   # kg m^2: a tapered blade and the bell (0.8-1.3e-4, the blade model 1.0e-4) to
#                                  Table 2's disk model, the upper end
ESC_HZ = 449.0              # the ESC's input frame rate (paper, sec. 4.4.1): a command waits 0 to 1/449 s
N_BLADES = 2
TAU_MOTOR = 0.035           # s, the as-flown choice: where the paper's real-flight facts hold (docs/as-flown.md)
TAU_RANGE = (0.020, None)   # s: fast ESCs and small rotors (INDIflight's 20 ms bench); the top is derived below
K_OVER_M = (0.3, 0.6)       # 1/s: rotor drag over mass measured on quadrotors (issue 17's review, docs/as-flown.md)
TAU_TILT_AIR = 8192 / 450.0 # s, the in-flight accelerometer correction: 8192 dt, long beside M/k (docs/estimator.md)


def derive(params: Params = Params()) -> dict:
    a = params.airframe
    B = a.M * a.g / 4                               # hover thrust per rotor (eq. 25's base)
    A = math.pi * a.rotor_radius ** 2
    v_h = math.sqrt(B / (2 * RHO * A))              # momentum theory, hover induced velocity
    omega_h = math.sqrt(B / a.c1)                   # eq. 27 at hover
    tip = omega_h * a.rotor_radius
    lam_h = v_h / tip
    sigma = BLADES * CHORD_75 / (math.pi * a.rotor_radius)
    a_sigma = LIFT_SLOPE * sigma
    # blade-element momentum theory, axial climb at fixed pitch and speed (Johnson, Helicopter
    # Theory, sec. 2-4; Padfield, Helicopter Flight Dynamics, heave damping):
    # dC_T/d(lambda_c) = 2 a sigma lambda_h / (16 lambda_h + a sigma), dT/dV = rho A (Omega R) dC_T/d(lambda_c)
    k_inflow = RHO * A * tip * 2 * a_sigma * lam_h / (16 * lam_h + a_sigma)
    k_inflow_max = 2 * RHO * A * v_h                # the same with a rigid thrust-pitch law (a sigma -> inf)
    # momentum drag: the rotor turns the free stream's horizontal momentum, mass flow rho A v_h
    k_drag = 4 * RHO * A * v_h
    # open-loop motor: J dW/dt = Kt (V - Ke W)/R - Q(W), linearised at hover
    ke = 60.0 / (2 * math.pi * KV)
    q_h = a.g1 * B + a.g2                           # eq. 28 at hover
    damping = ke * ke / R_PHASE + 2 * q_h / omega_h
    # a rigid rotor's hub moment from a body rate p: blade elements at (r, psi) meet the air p r sin psi
    # faster, lift -rho a c Omega r^2 p sin psi / 2 dr, arm r sin psi; averaged over psi, N_b blades:
    # -N_b rho a c Omega R^4 p / 16 per rotor (sim/causes/rotor_inflow.py)
    hub = 4 * N_BLADES * RHO * LIFT_SLOPE * CHORD_75 * omega_h * a.rotor_radius ** 4 / 16
    return {"M": a.M, "B": B, "v_h": v_h, "omega_h": omega_h, "lambda_h": lam_h, "sigma": sigma,
            "k_inflow": k_inflow, "k_inflow_max": k_inflow_max, "k_drag": k_drag, "M_over_k": a.M / k_drag,
            "tau_open_table2_Jp": a.Jp / damping, "tau_open_blade_J": J_BLADE_MODEL / damping,
            "tau_coast_blade_J": J_BLADE_MODEL / (2 * q_h / omega_h), "tau_coast_table2_Jp": a.Jp / (2 * q_h / omega_h),
            "hub": hub}


def as_flown(d: dict) -> Params:
    src_in = (f"theory: blade-element momentum, dT/dV at hover = {d['k_inflow']:.3f} N s/m per rotor "
              f"(v_h {d['v_h']:.2f} m/s, solidity {d['sigma']:.3f}, lift slope {LIFT_SLOPE}/rad; "
              f"rigid-pitch bound {d['k_inflow_max']:.2f}); scripts/as_flown.py")
    src_in += "; range: BEMT -30 % (lift slope, solidity) to the rigid-pitch bound"
    src_md = (f"not measured on this vehicle: 35 ms is where the paper's real-flight facts hold (both tables "
              f"fly, Table 6 settles; up to 45-50 ms), chosen from those facts, not from physics. Range: "
              f"{TAU_RANGE[0] * 1e3:.0f} ms (fast ESCs; INDIflight's 5-inch rotors: 20 ms bench, 26 ms in "
              f"flight) to the open-loop estimate Jp/(Kt Ke/R + 2Q/W) of {d['tau_open_table2_Jp']:.3f} s with "
              f"Table 2's Jp ({d['tau_open_blade_J']:.3f} s with a blade-model Jp; 170 ms measured for a "
              f"9.4-inch propeller); measure it with the bench step profile. The Monte Carlo moves the "
              f"top with the drawn Jp (at a given motor torque the time constant is proportional to Jp)")
    src_dr = (f"theory: momentum (ram) drag 4 rho A v_h = {d['k_drag']:.2f} N s/m (M/k = {d['M_over_k']:.2f} s), "
              f"an upper estimate; measured quadrotors give k/M = {K_OVER_M[0]:g}-{K_OVER_M[1]:g} 1/s "
              f"({K_OVER_M[0] * d['M']:.2f}-{K_OVER_M[1] * d['M']:.2f} N s/m here): the range runs from there "
              f"to the momentum value")
    src_md += (f"; tau_down (the rotor slowing down): the same as tau for an ESC that brakes (the E600's "
               f"sine-wave drive is taken to: not measured); one that does not lets it coast on its drag, "
               f"Jp/(2Q/W) = {d['tau_coast_blade_J']:.2f}-{d['tau_coast_table2_Jp']:.2f} s, outside the range drawn")
    src_dr += ("; yaw: it acts at the rotors, so it damps yaw, k l^2 r for four; the paper's yaw-drag rig spun "
               "the vehicle on rotors 1 and 3 with 2 and 4 off, so eq. 6's gamma1 holds the running pair's share: "
               "the file adds the other pair's, (k / 2) l^2, range 0 to k l^2 at the largest k")
    src_in += (f"; hub: a rigid rotor's hub moment N_b rho a c Omega R^4 / 16 per rotor, {d['hub']:.4f} N m s/rad "
               f"for four (an upper estimate: flapping relieves it; range down to 0)")
    period = 1.0 / ESC_HZ
    src_delay = (f"theory: the ESC samples its input at {ESC_HZ:g} Hz, unsynchronised with the 450 Hz loop, so a "
                 f"command waits 0 to {period * 1e3:.2f} ms for the next frame, {0.5 * period * 1e3:.2f} ms on "
                 f"average; range: none to two frames (the wait plus up to a frame of the ESC's own processing, "
                 f"not measured). The gyro's and accelerometer's DLPF delays (2.9 and 1.9 ms) are the simulated "
                 f"chip's (sim/world/devices.py), declared in its logs for diagnose")
    filters = dataclasses.replace(Filters(), tau_tilt_air=TAU_TILT_AIR)
    k_in, k_dr, hub = round(d["k_inflow"], 4), round(d["k_drag"], 3), round(d["hub"], 4)
    tau_hi = round(d["tau_open_table2_Jp"], 3)
    l2 = Params().airframe.l ** 2
    return Params(airframe=dataclasses.replace(Params().airframe, Jp=J_BLADE_MODEL), filters=filters,
                  ranges=(("Jp", *J_RANGE),), effects=(
        EffectSpec("rotor_inflow", (("k", k_in), ("hub", hub)), src_in,
                   (("k", round(0.7 * k_in, 4), round(d["k_inflow_max"], 4)), ("hub", 0.0, hub))),
        EffectSpec("motor_dynamics", (("tau", TAU_MOTOR), ("tau_down", TAU_MOTOR)), src_md,
                   (("tau", TAU_RANGE[0], tau_hi), ("tau_down", TAU_RANGE[0], tau_hi))),
        EffectSpec("rotor_drag", (("k", k_dr), ("yaw", round(0.5 * k_dr * l2, 5))), src_dr,
                   (("k", round(K_OVER_M[0] * d['M'], 3), k_dr), ("yaw", 0.0, round(k_dr * l2, 5)))),
        EffectSpec("actuation_delay", (("delay", round(0.5 * period, 6)),), src_delay,
                   (("delay", 0.0, round(2 * period, 6)),))))


def sources(d: dict) -> dict[str, str]:
    """The airframe values the as-flown file changes, with their provenance."""
    return {"Jp": (f"one rotor inertia for tau, the reaction torque and eq. 7-9: a 13 g 12-inch propeller as a "
                   f"rod (m R^2 / 3) plus the bell, {J_BLADE_MODEL:.1e}; range (range.Jp, drawn) {J_RANGE[0]:.1e} "
                   f"(a tapered blade: 0.8-1.3e-4 with the bell) to Table 2's disk model {J_RANGE[1]:.3e}, which gives the "
                   f"open-loop tau of {d['tau_open_table2_Jp']:.3f} s at the top of tau's range "
                   f"({d['tau_open_blade_J']:.3f} s with this Jp: a draw's tau is at most 0.192 s x Jp / 2.668e-4)")}


def main() -> None:
    import argparse
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=str(Path(__file__).resolve().parents[1] / "flightctl" / "vehicles" /
                                         "paper-as-flown.toml"),
                    help="the parameter file to write (default: the checkout's flightctl/vehicles/paper-as-flown.toml, "
                         "never the installed package's)")
    args = ap.parse_args()
    d = derive()
    for k, v in d.items():
        print(f"{k:>20} = {v:.4g}")
    path = Path(args.out)
    text = ("# The paper's vehicle as flown: the reference airframe (conventions.md) plus the terms its\n"
            "# model lacks, each with its provenance. Written by scripts/as_flown.py; do not edit by hand.\n"
            + dumps(as_flown(d), sources(d), tables=("filters",)))
    path.write_text(text)
    print(f"-> {Path(path).relative_to(Path.cwd()) if path.is_relative_to(Path.cwd()) else path}")


if __name__ == "__main__":
    main()
