"""The simulated world: the model and its integrator (compiled where numba is installed), the simulated
devices at their lowest boundary, the board that wires them to the real drivers, and the faults injected
there."""
