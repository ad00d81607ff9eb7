"""matching stages."""
