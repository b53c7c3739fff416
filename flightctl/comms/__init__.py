"""Links off the vehicle: MAVLink to a ground station, the hardware-in-the-loop link, and the frames of both edges."""
