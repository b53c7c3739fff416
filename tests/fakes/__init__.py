"""Fakes that speak the real protocols, for the real client libraries (pigpio, smbus2-like buses)."""
