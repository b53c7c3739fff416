"""Flights and their metrics: flying a plan against the simulated board, the named scenarios and their
measured steps, the step metrics, and the fault matrix."""
