"""spinefarm sim."""
