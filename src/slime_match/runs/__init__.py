"""Runs over many pairs and what they write: a pair's output folder (:mod:`.outputs`), pairs files
(:mod:`.pair_lists`), batch runs (:mod:`.batch`, scheduled by :mod:`.schedule`, on a Ray cluster by
:mod:`.ray_backend`, split by :mod:`.shards`, recorded by :mod:`.index`) and their exports to
structure-from-motion tools (:mod:`.export`, :mod:`.colmap`, :mod:`.hloc`)."""
