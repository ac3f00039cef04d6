"""Limits and fixed key paths of scene files: every file is accepted or refused within them."""

MAX_SCENE_BYTES = 32_768
"""Largest scene file read, bytes (the built-in scenes take 1-4 kB); bounds the parsing time."""
MAX_MAGNITUDE = 1e6
"""Largest magnitude accepted for any number in a scene (SI units)."""
MAX_LINKS = 64
"""Largest number of links in one scene."""
MAX_CLOSURES = 64
"""Largest number of closures in one scene."""
MAX_NESTING = 32
"""Deepest nesting of YAML collections accepted (a scene needs 6)."""
MAX_MERGED_ENTRIES = 10_000
"""Largest number of entries that YAML merge keys (``<<: *anchor``) may copy in one document."""
MAX_STRING = 200
"""Longest name or other short string, characters."""
DEFAULT_CLOSURE_TOLERANCE = 1e-6
"""Largest closure residual accepted at t = 0 without assembly, m or rad."""
FILE_KEY = "(file)"
"""Key path of errors about the file as a whole (missing, unreadable, too large)."""
TOP_KEY = "(top level)"
"""Key path of the document itself."""

TOP_KEYS = {
    "name", "description", "provenance", "units", "gravity", "chains", "closures", "actuators",
    "points", "loads", "closure_method", "assemble", "defaults", "sensors",
}

