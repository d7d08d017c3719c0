"""spinefarm storage."""
