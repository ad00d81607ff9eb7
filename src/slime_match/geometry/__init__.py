"""geometry stages."""
