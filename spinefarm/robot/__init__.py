"""What a robot is, apart from any engine: morphology specs, rigid-body data, controller spaces, trial
configuration and scenes. Imports neither pybullet nor numba, so a coordinator can define a run."""
