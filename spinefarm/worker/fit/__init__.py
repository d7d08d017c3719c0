"""Fitting a robot's physical constants to recorded motion: the recording format and its readers, short
windows started from the recorded state (multiple shooting), and the search over constants."""
