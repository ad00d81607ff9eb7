"""``python -m slime_match.cli``: the ``slime`` command."""

import sys

from .commands import main

sys.exit(main())
