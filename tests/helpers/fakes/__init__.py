"""Fakes that speak the real protocols, for the real client libraries (a pigpiod for pigpio). The I2C
bus and its INA219 are the simulator's own (`flightctl.sim.world.power`), one simulated chip for tests and flights."""

# The HC-SR04 module as both fakes with GPIO lines answer it (fakes/pigpiod.py, fakes/gpiochip.py): the
# echo rises this long after the trigger pulse ends and stays high this long per metre of distance.
HCSR04_ECHO_DELAY_US = 450.0
HCSR04_US_PER_M = 5831.0
