import os
import sys

# tests/ helpers (shapes.py) importable as plain modules
sys.path.insert(0, os.path.dirname(__file__))

# Property tests: random examples on a developer's machine (they find new cases), the same examples
# on every CI run (a red CI run is then the change's, not a new random draw's).
try:
    from hypothesis import settings as _hypothesis_settings
except ImportError:  # the oldest-pins environments may run without hypothesis
    pass
else:
    _hypothesis_settings.register_profile("ci", derandomize=True, print_blob=True)
    if os.environ.get("CI"):
        _hypothesis_settings.load_profile("ci")
