"""The names that options accept, defined once for the code that implements them and for the command line.

This module imports nothing, so that building the ``slime`` command's parser (``slime --help``,
``slime --version``) loads neither torch, numba nor OpenCV. Each tuple is re-exported by the module that
implements its choices (``features.descriptors.DESCRIPTOR_CHOICES`` ...).
"""

DEVICES = ("auto", "cpu", "cuda")

# the base pipelines built into the package, in their registration order (``pipelines.registry``); each is also
# a method that runs that pipeline alone. Pipelines registered at run time are known to the Python API only.
BUILTIN_BASES = ("hz+", "rootsift", "keynet")
# the learned bases (kornia's ALIKED, DISK, XFeat with LightGlue or mutual nearest neighbours), registered after
# them; alone or inside Slime (``pipelines.learned``)
LEARNED_BASES = ("aliked-lg", "aliked-nn", "disk-lg", "disk-nn", "xfeat-lg", "xfeat-nn")
ALIKED_MODELS = ("n16", "n16rot", "n32")
# the presets of ``make_config`` and ``slime match --method`` (``config.PRESETS`` holds their settings)
PRESET_NAMES = ("slime", "slime-upright", "slime-rootsift", "slime-fast", "slime-fine", "slime-keynet",
                "slime-keynet-upright", "slime-aliked", "slime-aliked-disk", "hz+", "hz+-upright", "rootsift",
                "rootsift-upright", "keynet", "keynet-upright", *LEARNED_BASES)
METHOD_CHOICES = ("auto", *PRESET_NAMES)  # "auto": the best preset whose weights are available (auto_method)

SHAPE_METHODS = ("affnet", "baumberg")
ORIENTATION_METHODS = ("orinet", "gradient", "upright", "fixed")
ORIENTATION_CHOICES = ORIENTATION_METHODS[:3]  # what a configuration may name ("fixed" is Slime's own)
DESCRIPTOR_METHODS = ("hardnet", "hardtfeat", "tfeat", "rootsift")
DESCRIPTOR_CHOICES = ("auto", *DESCRIPTOR_METHODS)  # "auto": the best available (features.descriptors)

RANSAC_KINDS = ("homography", "fundamental")
RANSAC_BACKENDS = ("slime", "magsac", "poselib")
# a configuration's post-processing RANSAC: none, or a kind by the paper's RANSACs or backend-kind
RANSAC_CHOICES = ("none", *RANSAC_KINDS,
                  *(f"{backend}-{kind}" for backend in RANSAC_BACKENDS[1:] for kind in RANSAC_KINDS))

DETECTIONS = ("scale", "block", "merged")  # how Slime's blocks get keypoints (slime.levels)
TILE_TESTS = ("plane", "flow")  # Sec. 3.8's test of tile matches; "flow" is the paper's, "plane" the default
VIEW_MODES = ("off", "auto", "always")  # simulated views (views.ViewConfig)
VIEW_IMAGES = ("image0", "image1", "both")  # which images get simulated views (views.ViewConfig)

# the flat options of one match (make_config's names) that the command line and the web app both offer, with
# their choices (None: a value read by the option's type); the command line also takes method and weights_dir
QUARTER_TURN_MODES = ("auto", "off")  # Slime's check of how image 1 is turned (quarter_turns)
# Slime on Hz+ where an upright base finds no match; "edge-on": also where it shows no tilt (rotation_fallback)
ROTATION_FALLBACK_MODES = ("auto", "edge-on", "off")
MATCH_OPTIONS = {
    "base": (*BUILTIN_BASES, *LEARNED_BASES), "descriptor": DESCRIPTOR_CHOICES, "shape": SHAPE_METHODS,
    "orientation": ORIENTATION_CHOICES, "upright": None, "ransac": RANSAC_CHOICES, "threshold": None,
    "seed": None, "device": DEVICES, "min_side": None, "max_side": None, "scales": None, "detection": DETECTIONS,
    "tile_test": TILE_TESTS, "magnification": None, "views": VIEW_MODES, "quarter_turns": QUARTER_TURN_MODES,
    "rotation_fallback": ROTATION_FALLBACK_MODES, "workers": None,
}

BATCH_BACKENDS = ("local", "ray")  # where `slime pairs` matches its pairs (runs.batch)

CAMERA_MODES = ("auto", "single", "per-folder", "per-image")  # COLMAP camera sharing (runs.colmap)

# the methods of the paper's comparison, the default of ``slime bench --methods`` (eval.methods)
PAPER_METHODS = (
    "rootsift",
    "rootsift-upright",
    "slime-rootsift",
    "keynet",
    "keynet-upright",
    "slime-keynet",
    "slime-keynet-upright",
    "hz+",
    "hz+-upright",
    "slime",
    "slime-upright",
    "opencv-sift",
)
