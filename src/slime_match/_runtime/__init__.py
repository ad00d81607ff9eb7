"""Process-level helpers of the package (private): forked worker maps."""
