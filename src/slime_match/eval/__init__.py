"""eval stages."""
