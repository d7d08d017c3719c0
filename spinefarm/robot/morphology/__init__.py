"""spinefarm morphology."""
