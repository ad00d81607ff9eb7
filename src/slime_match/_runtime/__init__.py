"""Helpers of the package itself (private): forked worker maps, the CPUs a process may use, stage timers,
configuration dataclasses from dicts and dotted names, the OpenMP spin default, and the compiled loops'
shared decorator, warm-ups and first-compile notice."""
