"""The Cura extension: settings, the after-slice hook, the save fallback, messages.

Flow (cura-plugin-api.md §1-2):

1. Settings are grafted into the Infill category as Cura loads definitions
   (``settings_injector``), and made visible once.
2. When the backend reports Done, the pass is deferred with ``callLater`` so
   Cura first fills in its own placeholders; then the scene's settings are read
   on the main thread (``snapshot``) and a background ``ProcessGCodeJob`` works
   on a copy of ``scene.gcode_dict[plate]`` with a progress message.
3. The result is written back only if that list is still the current one.
4. If the user saves first, ``writeStarted`` waits for the job (or processes
   synchronously), so the file always has the new infill.
5. The processed marker in the header makes every step idempotent; G-code
   loaded from a file is never touched.
6. After a write-back, the callbacks registered with ``addProcessedCallback``
   run on the main thread (layer preview and estimates hook in here).
"""

from __future__ import annotations

import importlib
import sys
import time

from UM.Application import Application
from UM.Extension import Extension
from UM.Logger import Logger
from UM.Message import Message

from .settings_injector import SettingsInjector, make_settings_visible

#: Written into the header by the G-code pass (see docs/gcode.md).
PROCESSED_MARKER = ";DELAUNAYINFILL_PROCESSED"
TITLE = "Delaunay variable infill"
BACKEND_DONE = 3  # UM.Backend.Backend.BackendState.Done, the same in Uranium 4.13 to 5.x
#: Modules in this package that may hook into the extension with ``install(extension)``.
OPTIONAL_HOOK_MODULES = ("preview", "estimates")
#: A save waits at most this long for a running background job.
SAVE_WAIT_SECONDS = 600.0

_instance = None


def get_extension():
    """The running extension (None before Cura registered the plugin)."""
    return _instance


def _message_type(name: str):
    kinds = getattr(Message, "MessageType", None)  # Uranium 4.10+; absent in older versions
    return getattr(kinds, name, None) if kinds is not None else None


def _show_message(text: str, kind: str = "WARNING", lifetime: int = 0) -> Message:
    kwargs = {"title": TITLE, "lifetime": lifetime}
    message_type = _message_type(kind)
    if message_type is not None:
        kwargs["message_type"] = message_type
    message = Message(text, **kwargs)
    message.show()
    return message


class DelaunayInfillExtension(Extension):
    """Runs the Delaunay infill pass on Cura's G-code after each slice."""

    def __init__(self) -> None:
        super().__init__()
        global _instance
        _instance = self
        self._application = Application.getInstance()
        self._processed_callbacks: list = []
        self._job = None
        self._progress_message = None
        self._failed_list = None  # the G-code list whose processing failed (no retry loop)
        self._dependency_error: str | None = None
        self._last_estimates: dict = {}  # plate -> (times_per_feature, material_amounts)
        self._applying = False  # True while our own write-back re-emits estimates and runs callbacks
        self._backend = None
        self._backend_state = None  # last BackendState seen; the G-code is complete only at Done
        self._injector = None
        try:
            self._injector = SettingsInjector()
        except Exception:
            Logger.logException("e", "DelaunayInfill: could not load the setting definitions")
        self._application.initializationFinished.connect(self._onInitialized)

    # -- public hook -------------------------------------------------------------------------
    def addProcessedCallback(self, callback) -> None:
        """Call ``callback(plate, gcode_list, report)`` after each write-back.

        It runs on Cura's main thread, after ``scene.gcode_dict[plate]`` holds
        the processed G-code (the same list object, changed in place).
        """
        if callback not in self._processed_callbacks:
            self._processed_callbacks.append(callback)

    def removeProcessedCallback(self, callback) -> None:
        if callback in self._processed_callbacks:
            self._processed_callbacks.remove(callback)

    def getLastEstimates(self, plate: int = 0):
        """Cura's own (times_per_feature, material_amounts) of the last slice of `plate`."""
        return self._last_estimates.get(plate)

    # -- start-up ------------------------------------------------------------------------------
    def _onInitialized(self) -> None:
        if self._injector is not None:
            self._injector.injectIntoLoaded()
            try:
                make_settings_visible(self._application.getPreferences(), self._injector.keys)
            except Exception:
                Logger.logException("w", "DelaunayInfill: could not make the settings visible")
        self._application.callLater(self._connect)

    def _connect(self) -> None:
        self._dependency_error = self._checkDependencies()
        if self._dependency_error:
            Logger.log("w", "DelaunayInfill: disabled: %s", self._dependency_error)
            _show_message(self._dependency_error, "ERROR")
            return
        self._backend = self._application.getBackend()
        if self._backend is None:
            Logger.log("e", "DelaunayInfill: Cura has no slicing backend; the plugin stays idle")
            return
        self._backend.backendStateChange.connect(self._onBackendStateChange)
        if hasattr(self._backend, "slicingStarted"):
            self._backend.slicingStarted.connect(self._onSlicingStarted)
        if hasattr(self._backend, "printDurationMessage"):
            self._backend.printDurationMessage.connect(self._onPrintDurationMessage)
        self._application.getOutputDeviceManager().writeStarted.connect(self._onWriteStarted)
        self._installOptionalHooks()
        Logger.log("i", "DelaunayInfill: ready (settings: %s)", ", ".join(self._injector.keys if self._injector else []))

    @staticmethod
    def _checkDependencies() -> str | None:
        if sys.version_info < (3, 10):  # noqa: UP036 - Cura 4.13 bundles (Windows, macOS, AppImage) run Python 3.8
            return (
                "Delaunay variable infill needs Cura running on Python 3.10 or later (Cura 5.1 and later, or a "
                f"Linux distribution's Cura 4.13); this Cura runs Python {sys.version.split()[0]}. Cura's own infill is used."
            )
        missing = []
        for module in ("numpy", "scipy.spatial", "shapely.geometry"):
            try:
                importlib.import_module(module)
            except Exception:
                missing.append(module.split(".")[0])
        if not missing:
            return None
        return (
            f"Delaunay variable infill needs the Python package(s) {', '.join(missing)}, which this Cura "
            "does not include. Cura's own infill is used; update Cura (5.1 or later) to use the plugin."
        )

    def _installOptionalHooks(self) -> None:
        package = __name__.rsplit(".", 1)[0]
        for name in OPTIONAL_HOOK_MODULES:
            try:
                module = importlib.import_module("." + name, package)
            except ModuleNotFoundError as error:
                if error.name and error.name.endswith("." + name):
                    continue  # not written (yet): nothing to install
                Logger.logException("e", "DelaunayInfill: could not import %s", name)
                continue
            except Exception:
                Logger.logException("e", "DelaunayInfill: could not import %s", name)
                continue
            install = getattr(module, "install", None)
            if callable(install):
                try:
                    install(self)
                except Exception:
                    Logger.logException("e", "DelaunayInfill: %s.install failed", name)

    # -- Cura signals ----------------------------------------------------------------------
    def _onPrintDurationMessage(self, plate, times_per_feature, material_amounts) -> None:
        # Keep CuraEngine's own figures; corrected ones emitted after a write-back are not originals.
        if times_per_feature and not self._applying:
            self._last_estimates[plate] = (dict(times_per_feature), list(material_amounts))

    def _onSlicingStarted(self) -> None:
        # The old list is replaced by a new one; the running job's result would not match it.
        if self._job is not None and not self._job.applied:
            self._job.cancelled = True
        self._hideProgress()

    def _onBackendStateChange(self, state) -> None:
        self._backend_state = int(state)
        if self._backend_state == BACKEND_DONE:
            # Deferred: Cura replaces its {print_time}-style placeholders after emitting Done.
            self._application.callLater(self._onSliceDone)

    def _onSliceDone(self) -> None:
        if self._backend_state != BACKEND_DONE:
            return  # a new slice started in the meantime
        try:
            self._startJob()
        except Exception:
            Logger.logException("e", "DelaunayInfill: could not start processing")
            _show_message("Delaunay variable infill could not start. The G-code keeps Cura's own infill.")

    def _onWriteStarted(self, *args) -> None:
        """Saving or printing: make sure the written G-code is the processed one."""
        try:
            if self._backend_state != BACKEND_DONE:
                return  # no complete slice (e.g. a project saved while slicing): nothing to process
            plate, gcode_list = self._currentGCode()
            if gcode_list is None or self._isDone(gcode_list):
                return
            job = self._job
            if job is not None and job.source_list is gcode_list and not job.applied:
                Logger.log("i", "DelaunayInfill: a save waits for the processing of this slice to finish")
                self._waitFor(job)
                self._applyJob(job)
                return
            snapshot = self._snapshot(plate)
            if snapshot is None:
                return
            from .job import ProcessGCodeJob

            sync_job = ProcessGCodeJob(plate, gcode_list, snapshot)
            Logger.log("i", "DelaunayInfill: processing on save (the slice had not been processed yet)")
            sync_job.run()
            self._applyJob(sync_job)
        except Exception:
            Logger.logException("e", "DelaunayInfill: processing on save failed")
            _show_message("Delaunay variable infill failed while saving. The file keeps Cura's own infill.")

    # -- the pass ------------------------------------------------------------------------------
    def _scene(self):
        return self._application.getController().getScene()

    def _activePlate(self) -> int:
        try:
            return int(self._application.getMultiBuildPlateModel().activeBuildPlate)
        except Exception:
            return 0

    def _currentGCode(self):
        """(plate, list) of the active plate's sliced G-code, or (plate, None)."""
        plate = self._activePlate()
        gcode_dict = getattr(self._scene(), "gcode_dict", None)
        if not isinstance(gcode_dict, dict):
            return plate, None
        gcode_list = gcode_dict.get(plate)
        if not isinstance(gcode_list, list) or len(gcode_list) < 3 or self._isLoadedGCode():
            return plate, None
        return plate, gcode_list

    def _isLoadedGCode(self) -> bool:
        """True when the scene shows a G-code file that the user opened."""
        from UM.Scene.Iterator.DepthFirstIterator import DepthFirstIterator

        return any(node.callDecoration("getGCodeList") is not None for node in DepthFirstIterator(self._scene().getRoot()))

    def _isDone(self, gcode_list: list) -> bool:
        return PROCESSED_MARKER in gcode_list[0] or gcode_list is self._failed_list

    def _snapshot(self, plate: int):
        """Cura's settings for this slice, or None when no model has the setting on."""
        from .snapshot import take_snapshot

        snapshot = take_snapshot(self._application, plate)
        if snapshot.ambiguous_names:
            _show_message(
                f"Several models are called {', '.join(sorted(snapshot.ambiguous_names))} but not all of them "
                "have Delaunay variable infill on. Give each model a unique name; their infill stays Cura's own."
            )
        if not any(not mesh.is_region for mesh in snapshot.enabled_meshes):
            return None
        return snapshot

    def _startJob(self) -> None:
        plate, gcode_list = self._currentGCode()
        if gcode_list is None or self._isDone(gcode_list):
            return
        if self._job is not None and self._job.source_list is gcode_list and not self._job.applied:
            return  # already working on this one ("slice unnecessary" re-emits Done)
        snapshot = self._snapshot(plate)
        if snapshot is None:
            return
        from .job import ProcessGCodeJob

        job = ProcessGCodeJob(plate, gcode_list, snapshot)
        job.progress.connect(self._onJobProgress)
        job.finished.connect(self._onJobFinished)
        self._job = job
        names = ", ".join(sorted({m.name for m in snapshot.enabled_meshes if not m.is_region}))
        self._hideProgress()
        self._progress_message = Message(
            f"Replacing the infill of {names}…", title=TITLE, lifetime=0, dismissable=False, progress=0
        )
        self._progress_message.show()
        job.start()

    def _onJobProgress(self, job, amount) -> None:
        if job is self._job and self._progress_message is not None:
            self._progress_message.setProgress(amount)

    def _onJobFinished(self, job) -> None:
        if job is self._job:
            self._hideProgress()
        if not job.applied:
            self._applyJob(job)

    @staticmethod
    def _waitFor(job) -> None:
        """Block the main thread until `job` finished (a save is waiting for it)."""
        from UM.JobQueue import JobQueue

        if not job.isRunning() and not job.isFinished():
            JobQueue.getInstance().remove(job)  # not started yet: run it right here
            if not job.isRunning() and not job.isFinished():
                job.run()
                return
        deadline = time.monotonic() + SAVE_WAIT_SECONDS
        while not job.isFinished() and time.monotonic() < deadline:
            time.sleep(0.02)

    def _applyJob(self, job) -> None:
        """Write the job's result back if its G-code is still the current one."""
        job.applied = True
        if job.cancelled:
            return  # a new slice started; its own Done will be processed
        gcode_dict = getattr(self._scene(), "gcode_dict", None)
        current = gcode_dict.get(job.plate) if isinstance(gcode_dict, dict) else None
        if current is not job.source_list:
            Logger.log("i", "DelaunayInfill: discarded a result for G-code that was replaced meanwhile")
            return
        if PROCESSED_MARKER in current[0]:
            return
        if job.hasError() or not job.layers_out:
            self._failed_list = current
            error = job.getError()
            Logger.log("e", "DelaunayInfill: processing failed: %r", error)
            _show_message(
                f"Delaunay variable infill could not process this slice ({_plain(error)}). "
                "The G-code keeps Cura's own infill."
            )
            return
        current[:] = job.layers_out  # in place: anyone holding this list sees the new G-code
        Logger.log("i", "DelaunayInfill: wrote back %d G-code chunks after %.2f s", len(current), job.seconds)
        self._reportKeptLayers(job.report)
        self._applying = True
        try:
            self._reEmitEstimates(job)
            for callback in list(self._processed_callbacks):
                try:
                    callback(job.plate, current, job.report)
                except Exception:
                    Logger.logException("e", "DelaunayInfill: a processed-G-code callback failed")
        finally:
            self._applying = False

    def _reportKeptLayers(self, report) -> None:
        from .adapter import failed_layers, kept_message

        layers = failed_layers(report)
        if layers:
            shown = ", ".join(str(n) for n in layers[:12]) + (" …" if len(layers) > 12 else "")
            _show_message(
                f"{len(layers)} layer(s) keep Cura's own infill because the Delaunay infill could not be "
                f"made there (layers {shown}).",
                lifetime=30,
            )
        kept = kept_message(report)
        if kept:
            _show_message(kept, lifetime=30)

    def _reEmitEstimates(self, job) -> None:
        """Tell Cura's print information the new infill time and material."""
        from .adapter import adjusted_estimates

        plate = job.plate
        original = self._last_estimates.get(plate)
        if original is None or self._backend is None:
            return
        adjusted = adjusted_estimates(original[0], original[1], job.report, job.snapshot)
        if adjusted is None:
            return
        times, amounts = adjusted
        self._backend.printDurationMessage.emit(plate, times, amounts)

    def _hideProgress(self) -> None:
        if self._progress_message is not None:
            self._progress_message.hide()
            self._progress_message = None


def _plain(error) -> str:
    text = str(error) if error is not None else ""
    return text.strip().rstrip(".") or "an internal error"
