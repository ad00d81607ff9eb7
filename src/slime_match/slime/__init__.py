"""slime stages."""
