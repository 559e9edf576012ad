"""The plugin in the real Cura 5.0 (Debian trixie: PyQt6, Uranium 5.0, CuraEngine 5.0, Python 3.13).

The same session and the same checks as test_gui_plugin.py (Cura 4.13), run in the
Cura 5.0 of the trixie chroot (scripts/cura5_chroot.sh): the setting in the Infill
category, slice, save through Cura's write path, the saved G-code checked with the
engine tier's checker, setting off gives Cura's G-code byte for byte, one model on
and one off, a failing pass, an opened G-code file, a Cura without shapely.
"""

from __future__ import annotations

import pytest
from test_gui_plugin import *  # noqa: F401,F403 - the same tests, on this module's session
from test_gui_plugin import start_session


@pytest.fixture(scope="module")
def session(gui_artifacts, gui_models):
    return start_session(gui_artifacts, gui_models, version="5.0", name="cura5-plugin")
