"""flightctl: the onboard flight controller of the paper's quadcopter (Rible, Arriola and Ramos)."""
__version__ = "0.1.0"
