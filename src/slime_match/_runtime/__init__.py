"""Process-level helpers of the package (private): forked worker maps, the CPUs a process may use, stage
timers, the OpenMP spin default and the numba compile notice."""
