"""spinefarm api."""
