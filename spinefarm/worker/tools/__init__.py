"""Tools a user runs over trials: calibrate, accuracy, replay, verify, render, video, picture, contract."""
