"""slime-match: image matching by bare homography (Slime) and its base pipelines."""

__version__ = "0.1.0"
