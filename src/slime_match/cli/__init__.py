"""The ``slime`` command line: :func:`main` (the entry point) and its parser."""

from .commands import build_parser, main

__all__ = ["build_parser", "main"]
