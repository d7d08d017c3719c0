"""The trial core: one trial, or a batch of worlds, from a parameter set to a scored result."""
