"""spinefarm cli."""
