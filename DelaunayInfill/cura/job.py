"""The background job that runs the G-code pass on one build plate's G-code.

The job works on a copy of Cura's list and plain-data settings (a
``SceneSnapshot`` taken on the main thread), so it never touches Cura's scene
or stacks from its worker thread.  Its result is applied by the extension on
the main thread, and only if that G-code is still the current one.
"""

from __future__ import annotations

import time

from UM.Job import Job
from UM.Logger import Logger


class ProcessGCodeJob(Job):
    """Run the Delaunay G-code pass in one of Uranium's worker threads.

    Parameters
    ----------
    plate : int
        Build plate number (the key in ``scene.gcode_dict``).
    source_list : list of str
        The list object in ``gcode_dict[plate]`` when the job was made; its
        identity is how the result is matched to the current G-code.
    snapshot : SceneSnapshot
        Cura's settings, read on the main thread.
    """

    def __init__(self, plate: int, source_list: list, snapshot) -> None:
        super().__init__()
        self.plate = plate
        self.source_list = source_list
        self.layers_in = list(source_list)  # the copy we work on
        self.snapshot = snapshot
        self.layers_out: list | None = None
        self.report = None
        self.seconds = 0.0
        self.fraction_done = 0.0
        self.applied = False  # set by the extension once written back (or discarded)
        self.cancelled = False  # set when a new slice makes this G-code obsolete

    def run(self) -> None:
        t0 = time.monotonic()
        try:
            from .adapter import run_pipeline

            self.layers_out, self.report = run_pipeline(
                self.layers_in, self.snapshot, progress=self._progress, cancel=self._isCancelled
            )
        except Exception as error:  # reported to the user by the extension; Cura's G-code stays
            if not self.cancelled:
                Logger.logException("e", "DelaunayInfill: processing the G-code failed")
            self.setError(error)
        finally:
            self.seconds = time.monotonic() - t0

    def _isCancelled(self) -> bool:
        return self.cancelled

    def _progress(self, fraction: float) -> None:
        self.fraction_done = max(0.0, min(1.0, float(fraction)))
        self.progress.emit(self, int(round(self.fraction_done * 100)))
        Job.yieldThread()  # let Cura's UI thread breathe between layers
