"""spinefarm samplers."""
