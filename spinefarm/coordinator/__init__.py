"""spinefarm coordinator."""
