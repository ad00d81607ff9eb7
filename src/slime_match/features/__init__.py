"""features stages."""
