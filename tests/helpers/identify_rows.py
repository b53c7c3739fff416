"""Well-formed rows of the identify inputs (bench, yaw-drag, pendulum, rotor), for the tests that break
them one cell at a time (tests/sim/identify/test_identify_errors.py, tests/onboard/test_fuzz_readers.py)."""
import numpy as np

HEADER = {"bench": "motor,P,thrust,omega,voltage,current", "yaw-drag": "torque,yaw_rate",
          "pendulum": "axis,pivot_distance,period", "rotor": "rotor,part,mass,radius"}


def bench_rows(P=np.arange(130.0, 210.0, 10.0), motor=1):
    f = 1.49e-3 * (P - 120) ** 2
    w = np.sqrt(f / 1.47e-5)
    current = (0.02 * f + 0.002) * w / 14.8
    return [f"{motor},{p:g},{fi:.6g},{wi:.6g},14.8,{i:.6g}" for p, fi, wi, i in zip(P, f, w, current)]


def yaw_rows(rates=(-3, -2, -1.5, -1, 1, 1.5, 2, 3), gamma2=1.2e-3):
    return [f"{(4.86e-4 * r * r + gamma2) * np.sign(r):.6g},{r}" for r in rates]


PENDULUM = ["x,0.28,1.10", "x,0.28,1.11", "y,0.28,1.10", "y,0.28,1.11", "z,0.30,1.30", "z,0.30,1.31"]
ROTOR = ["1,blade,0.013,0.15", "1,motor,0.066,0.014", "2,blade,0.013,0.15", "2,motor,0.066,0.014"]
