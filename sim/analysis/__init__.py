"""The machinery of `flightctl analyze` (flightctl.sim.analysis.cli): `linear` linearises the plant
through the model seam and the onboard estimator as it runs; `loops` closes each loop as flown and
computes its figures."""
