"""The onboard service, `flightctl run` (run.py), with its plan queue (queue.py) and systemd's notify
socket (sdnotify.py); systemd/flightctl.service runs it on the quadcopter."""
