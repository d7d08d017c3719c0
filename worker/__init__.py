"""spinefarm worker."""
