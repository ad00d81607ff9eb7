"""Runs over many pairs and what they write: a pair's output folder (:mod:`.outputs`), pairs files
(:mod:`.pair_lists`), batch runs (:mod:`.batch`, scheduled by :mod:`.schedule`) and their exports to
structure-from-motion tools (:mod:`.export`, :mod:`.colmap`, :mod:`.hloc`)."""
