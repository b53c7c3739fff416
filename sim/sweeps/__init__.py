"""Many flights at once: the Monte Carlo over a parameter file's ranges, the batched simulator, and the automated tuning."""
