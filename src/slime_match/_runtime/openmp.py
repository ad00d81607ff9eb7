"""A short OpenMP spin for torch's CPU thread pool, set by the ``slime`` command before torch loads.

libgomp, the OpenMP runtime of PyTorch's Linux CPU wheels, lets a waiting worker thread spin 300,000 times
before it sleeps. When other processes keep the cores busy, the spinning thread holds a core while the thread
it waits for is descheduled, and torch's CPU work can slow down by one to two orders of magnitude
(docs/performance.md, "Busy machines"). 1,000 spins, libgomp's own value when threads outnumber cores, leave
the idle times unchanged.

libgomp reads the variable once, when torch loads it. The default is therefore set only when torch is not
imported yet, and never over the user's own GOMP_SPINCOUNT or OMP_WAIT_POLICY. Importing the package does not
set it: in Python, export ``GOMP_SPINCOUNT=1000`` before torch is imported.
"""

import os
import sys

SPIN_COUNT = "1000"


def set_default_spin_count() -> None:
    """Set GOMP_SPINCOUNT to SPIN_COUNT unless torch is already loaded or the user chose a wait policy."""
    if "torch" not in sys.modules and "GOMP_SPINCOUNT" not in os.environ and "OMP_WAIT_POLICY" not in os.environ:
        os.environ["GOMP_SPINCOUNT"] = SPIN_COUNT

