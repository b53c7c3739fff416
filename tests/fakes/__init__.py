"""Fakes that speak the real protocols, for the real client libraries (a pigpiod for pigpio). The I2C
bus and its INA219 are the simulator's own (`flightctl.sim.world.power`), one simulated chip for tests and flights."""
