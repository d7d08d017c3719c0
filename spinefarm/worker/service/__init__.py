"""The worker service: a Zenoh worker pulling leased trials and running each in a time-bounded child."""
