"""What the tests share: the real data's paths (real.py), the repository's (paths.py), the fakes at the
lowest boundary (fakes/), a script loaded as a module (script.py), a run without the Pi libraries
(without.py), the hand-measured frame (hand.py)."""
