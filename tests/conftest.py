import gzip
import os
import shutil
import sys

import pytest

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


@pytest.fixture()
def star_gcode(tmp_path):
    """The bundled CuraEngine 4.13 G-code of the five-point star, unpacked into the test's folder."""
    path = tmp_path / "star.gcode"
    data = os.path.join(os.path.dirname(__file__), "..", "DelaunayInfill", "data", "star.gcode.gz")
    with gzip.open(data, "rb") as src, open(path, "wb") as dst:
        shutil.copyfileobj(src, dst)
    return path
