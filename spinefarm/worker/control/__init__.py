"""spinefarm control."""
