"""Execute a JSON job inside a real Cura session (GUI test tier; never shipped).

Cura is started with ``DELAUNAY_GUI_JOB=/path/job.json``.  The job is a list of
actions, run in order on Cura's main thread once Cura has finished starting:

``{"do": "settings", "values": {key: value}}``
    User changes on the global stack, and on every extruder for
    ``settable_per_extruder`` keys; a string starting with "=" is a formula.
``{"do": "load", "file": "/abs/model.stl", "settings": {key: value}, "keep_position": true, "offset": [x, y]}``
    Read a model like File > Open; per-model settings go to the node's own
    stack like the Per Model Settings tool does.  ``keep_position`` (default
    true) undoes auto-arrange so STL X/Y 0 is the bed centre (plus ``offset``,
    mm in G-code X/Y).
``{"do": "open", "file": "/abs/print.gcode"}``
    Open a file as File > Open does, without touching the result (e.g. a G-code file).
``{"do": "model_settings", "model": "star.stl", "values": {key: value}}``
    Per-model settings on a model already in the scene.
``{"do": "slice", "timeout_s": 120}``
    ``forceSlice()`` and wait for the backend's Done.
``{"do": "wait_processed", "expect": true, "timeout_s": 120}``
    Wait until the plugin's marker is in the G-code header (expect true), or
    check it stays absent for ``settle_s`` seconds (expect false).
``{"do": "save", "path": "/abs/out.gcode"}``
    The normal write path: the local-file device's ``writeStarted`` (the plugin
    and post-processing scripts hook in there), then GCodeWriter, then
    ``writeFinished``.
``{"do": "dump_unprocessed", "path": "/abs/raw.gcode"}``
    Cura's own G-code of the last processed slice, as the plugin's job received it.
``{"do": "dump_engine_gcode", "path": "/abs/raw.gcode"}``
    The last slice's G-code as CuraEngine and Cura made it (copied one event-loop turn after
    the backend's Done, before a background pass can write back), processed or not.
``{"do": "inspect", "key": "delaunay_infill_enabled"}``
    Record where the setting lives (category, visibility, value) in the status.
``{"do": "resolve", "model": "star.stl", "keys": [...], "record": "resolved"}``
    Record Cura's resolved values of `keys` from the model's own stack.
``{"do": "stage", "name": "PreviewStage"}`` / ``{"do": "sleep", "s": 2}``
``{"do": "camera", "position": [x, y, z], "look_at": [x, y, z]}``
    Place the camera (Cura scene coordinates, mm, Y up).
``{"do": "layer", "layer": 25}``
    Show layers up to this one in Preview (layer view).
``{"do": "expect_reslice"}``
    Check that the last settings change made Cura drop the sliced G-code
    (the backend left Done), i.e. that it triggers a re-slice.
``{"do": "screenshot", "path": "/abs/x.png", "delay_s": 3}``
    The whole X screen, with ImageMagick's ``import -window root``.
``{"do": "step", "file": "/abs/steps_x.py", "function": "name", "args": {...}}``
    Call ``function(ctx, **args)`` from a Python file, on the main thread.  It
    may return a generator that yields waits (see below).  ``ctx`` is this
    driver: ``ctx.app``, ``ctx.log(msg)``, ``ctx.record(key, value)``,
    ``ctx.nodes()``, ``ctx.node(name)``, ``ctx.extension()`` (the plugin's),
    ``ctx.wait_until(predicate, timeout_s, what)``.

Top level: ``status`` (path of the status JSON, rewritten after every action),
``quit`` (close Cura at the end), ``timeout_s`` (whole job), ``start_delay_s``,
``font_scale`` (the application font times this, set before Cura builds its theme).
Every action's outcome is logged as "DelaunayGuiDriver: ..." in cura.log.

Waits: a generator yields either a number (sleep that many seconds) or a
``(predicate, timeout_s, what)`` tuple (poll until the predicate is true).
"""

from __future__ import annotations

import importlib.util
import json
import os
import socket
import subprocess
import time
import traceback

try:
    from PyQt6.QtCore import QTimer, QUrl
except ImportError:
    from PyQt5.QtCore import QTimer, QUrl

from UM.Application import Application
from UM.Extension import Extension
from UM.Logger import Logger

MARKER = ";DELAUNAYINFILL_PROCESSED"
TICK_MS = 100
BACKEND_STATES = {1: "NotStarted", 2: "Processing", 3: "Done", 4: "Error", 5: "Disabled"}


class _Timeout(Exception):
    pass


class GuiDriver(Extension):
    def __init__(self) -> None:
        super().__init__()
        self.app = Application.getInstance()
        self.job = None
        self.status = {"ok": None, "stage": "init", "actions_done": 0, "records": {}, "t0": time.time()}
        self._runner = None
        self._waiting = None  # (predicate, deadline, what) or a wake-up time (float)
        self._finished = False
        self._loaded_files: list = []
        self._backend_states: list = []
        self._engine_gcode = None  # the last slice's G-code as CuraEngine and Cura made it
        self._timer = QTimer()
        self._timer.setInterval(TICK_MS)
        self._timer.timeout.connect(self._tick)
        path = os.environ.get("DELAUNAY_GUI_JOB")
        if not path:
            return
        try:
            with open(path, encoding="utf-8") as stream:
                self.job = json.load(stream)
        except Exception as error:
            Logger.logException("e", "DelaunayGuiDriver: cannot read the job %s", path)
            self.status.update(ok=False, error=f"job file: {error}")
            return
        self.log(f"job {path} loaded")
        self._scaleFont(float(self.job.get("font_scale", 1.0)))
        self.app.initializationFinished.connect(self._onInitialized)

    def _scaleFont(self, scale: float) -> None:
        """A larger (or smaller) application font, as a user's desktop font setting gives Cura.

        Plugins are registered before Cura builds its theme, and the theme takes its font sizes
        and its em-based sizes from the application font, so this runs early enough.
        """
        if abs(scale - 1.0) < 1e-6:
            return
        try:
            from PyQt6.QtGui import QGuiApplication
        except ImportError:
            from PyQt5.QtGui import QGuiApplication
        font = QGuiApplication.font()
        size = font.pointSizeF()
        font.setPointSizeF(size * scale)
        QGuiApplication.setFont(font)
        self.log(f"application font {size:g} pt -> {font.pointSizeF():g} pt")

    # -- helpers for actions and step files ------------------------------------------------------
    def log(self, message: str) -> None:
        Logger.log("i", "DelaunayGuiDriver: %s", message)

    def record(self, key: str, value) -> None:
        self.status["records"][key] = value
        self._writeStatus()

    def nodes(self) -> list:
        from UM.Scene.Iterator.DepthFirstIterator import DepthFirstIterator

        root = self.app.getController().getScene().getRoot()
        return [n for n in DepthFirstIterator(root) if n.callDecoration("isSliceable")]

    def node(self, name: str):
        for node in self.nodes():
            if node.getName() == name:
                return node
        raise RuntimeError(f"no model named {name!r} in the scene")

    def extension(self):
        """The DelaunayInfill plugin's extension object (None if it did not load)."""
        import sys

        for name, module in list(sys.modules.items()):
            if name.endswith("DelaunayInfill.cura.extension") and hasattr(module, "get_extension"):
                return module.get_extension()
        return None

    def gcode_list(self):
        scene = self.app.getController().getScene()
        gcode_dict = getattr(scene, "gcode_dict", None) or {}
        plate = self.app.getMultiBuildPlateModel().activeBuildPlate
        return gcode_dict.get(plate)

    def wait_until(self, predicate, timeout_s: float = 60.0, what: str = "condition"):
        return (predicate, float(timeout_s), what)

    # -- the run loop --------------------------------------------------------------------------
    def _writeStatus(self) -> None:
        path = self.job.get("status") if self.job else None
        if not path:
            return
        self.status["elapsed_s"] = round(time.time() - self.status["t0"], 2)
        temp = path + ".tmp"
        with open(temp, "w", encoding="utf-8") as stream:
            json.dump(self.status, stream, indent=1, default=str)
        os.replace(temp, path)

    def _onInitialized(self) -> None:
        backend = self.app.getBackend()
        if backend is not None:
            backend.backendStateChange.connect(self._onBackendState)
        self.app.fileCompleted.connect(self._onFileCompleted)
        self._runner = self._run()
        self._waiting = time.time() + float(self.job.get("start_delay_s", 2.0))
        self._deadline = time.time() + float(self.job.get("timeout_s", 300))
        self._timer.start()

    def _onBackendState(self, state) -> None:
        self._backend_states.append(int(state))
        if int(state) == 3:
            # Cura fills in its header placeholders right after emitting Done; a deferred copy is
            # CuraEngine's G-code as Cura keeps it, before any plugin's background pass wrote back
            self.app.callLater(self._keepEngineGCode)

    def _keepEngineGCode(self) -> None:
        gcode = self.gcode_list()
        if gcode:
            self._engine_gcode = "".join(gcode)

    def _onFileCompleted(self, file_name) -> None:
        self._loaded_files.append(file_name)

    def _tick(self) -> None:
        if self._finished:
            return
        now = time.time()
        try:
            if now > self._deadline:
                raise _Timeout(f"job timeout in stage {self.status['stage']}")
            if isinstance(self._waiting, float):
                if now < self._waiting:
                    return
            elif self._waiting is not None:
                predicate, deadline, what = self._waiting
                if not predicate():
                    if now > deadline:
                        raise _Timeout(f"timed out waiting for {what}")
                    return
            self._waiting = None
            request = next(self._runner)
            if isinstance(request, (int, float)):
                self._waiting = now + float(request)
            elif isinstance(request, tuple):
                predicate, timeout_s, what = request
                self._waiting = (predicate, now + timeout_s, what)
        except StopIteration:
            self._complete()
        except Exception as error:
            Logger.logException("e", "DelaunayGuiDriver: FAILED")
            self.status.update(ok=False, error=f"{type(error).__name__}: {error}", traceback=traceback.format_exc())
            self._end()

    def _run(self):
        for index, action in enumerate(self.job.get("actions", [])):
            kind = action.get("do")
            self.status["stage"] = f"{index}:{kind}"
            self._writeStatus()
            self.log(f"action {index}: {kind}")
            handler = getattr(self, "_do_" + str(kind), None)
            if handler is None:
                raise RuntimeError(f"unknown action {kind!r}")
            result = handler(action)
            if result is not None and hasattr(result, "__next__"):
                yield from result
            self.status["actions_done"] = index + 1
            self._writeStatus()

    def _complete(self) -> None:
        self.log("DONE")
        self.status.update(ok=True, stage="done")
        self._end()

    def _end(self) -> None:
        self._finished = True
        self._timer.stop()
        self._writeStatus()
        if self.job.get("quit", True):
            self.log("quitting")
            QTimer.singleShot(300, self.app.closeApplication)

    # -- actions --------------------------------------------------------------------------------
    @staticmethod
    def _value(value):
        if isinstance(value, str) and value.startswith("="):
            from UM.Settings.SettingFunction import SettingFunction

            return SettingFunction(value[1:])
        return value

    def _do_settings(self, action):
        self._backend_states.clear()
        stack = self.app.getGlobalContainerStack()
        for key, value in action.get("values", {}).items():
            if stack.getProperty(key, "type") is None:
                raise RuntimeError(f"Cura has no setting {key!r}")
            stack.setProperty(key, "value", self._value(value))
            if stack.getProperty(key, "settable_per_extruder"):
                for extruder in stack.extruderList:
                    extruder.setProperty(key, "value", self._value(value))
            self.log(f"setting {key} = {value!r}")

    def _do_load(self, action):
        path = action["file"]
        before = len(self._loaded_files)
        self.app.readLocalFile(QUrl.fromLocalFile(path), add_to_recent_files=False)
        yield self.wait_until(lambda: len(self._loaded_files) > before, 60, f"loading {path}")
        yield 0.5
        name = os.path.basename(path)
        node = self.node(name)
        if action.get("keep_position", True):
            from UM.Math.Vector import Vector

            # G-code X/Y offset from the bed centre -> scene (x, 0, -y)
            dx, dy = action.get("offset", [0.0, 0.0])
            node.setPosition(Vector(float(dx), 0, -float(dy)))
        if action.get("settings"):
            self._setModelSettings(node, action["settings"])
        box = node.getBoundingBox()
        self.record(f"model:{name}", {"min": [box.left, box.bottom, box.back], "max": [box.right, box.top, box.front]})
        self.app.getController().getScene().sceneChanged.emit(node)

    def _do_open(self, action):
        before = len(self._loaded_files)
        self.app.readLocalFile(QUrl.fromLocalFile(action["file"]), add_to_recent_files=False)
        yield self.wait_until(lambda: len(self._loaded_files) > before, 60, f"opening {action['file']}")
        yield float(action.get("settle_s", 2.0))

    def _do_model_settings(self, action):
        node = self.node(action["model"])
        self._setModelSettings(node, action.get("values", {}))
        self.app.getController().getScene().sceneChanged.emit(node)

    def _setModelSettings(self, node, values: dict) -> None:
        from UM.Settings.SettingInstance import SettingInstance

        stack = node.callDecoration("getStack")
        if stack is None:
            from cura.Settings.SettingOverrideDecorator import SettingOverrideDecorator

            node.addDecorator(SettingOverrideDecorator())
            stack = node.callDecoration("getStack")
        top = stack.getTop()
        for key, value in values.items():
            definition = stack.getSettingDefinition(key)
            if definition is None:
                raise RuntimeError(f"Cura has no per-model setting {key!r}")
            instance = top.getInstance(key)
            if instance is None:
                instance = SettingInstance(definition, top)
                instance.setProperty("value", self._value(value))
                top.addInstance(instance)
            else:
                instance.setProperty("value", self._value(value))
            self.log(f"model {node.getName()}: {key} = {value!r}")

    def _do_slice(self, action):
        backend = self.app.getBackend()
        checker = self.app.getMachineErrorChecker()
        started = time.time()
        finished = lambda: any(state in (3, 4, 5) for state in self._backend_states)  # noqa: E731
        # Retried, because two things make a slice fail that a user never sees: (1) Cura schedules
        # its setting error check a moment after a change (the Slice button waits for it; forceSlice
        # right after a change can hit a stale result: state Error); (2) several Cura sessions on one
        # machine can collide on the engine's port, and Cura then restarts its engine but drops the slice.
        for attempt in range(int(action.get("attempts", 3))):
            yield 1.0
            yield self.wait_until(lambda: not checker.needToWaitForResult, 30, "Cura's setting error check")
            self._backend_states.clear()
            self._movePortAside(backend)
            backend.forceSlice()
            deadline = time.time() + float(action.get("attempt_s", 45))
            yield self.wait_until(lambda d=deadline: finished() or time.time() > d, action.get("timeout_s", 120),
                                  "the slice")
            if 3 in self._backend_states:
                break
            names = [BACKEND_STATES.get(s, s) for s in self._backend_states]
            self.log(f"slice attempt {attempt + 1} ended with backend states {names}; slicing again")
        if 3 not in self._backend_states:
            names = [BACKEND_STATES.get(s, s) for s in self._backend_states]
            raise RuntimeError(f"slicing did not finish: backend states {names}")
        self.record("slice_s", round(time.time() - started, 2))

    def _movePortAside(self, backend) -> None:
        """Have the next slice listen on a free port other than the one Cura listens on now.

        Cura 4.13 starts a slice by closing its listening socket and at once listening on the same
        port again; the close is not finished yet, the bind fails, and its error handler recreates
        the socket twice per failure, which cascades over the next ports and at times crashes Cura
        natively (segfault, no Python frame; reproduced by holding ports 49674-49676 busy, without
        this plugin doing anything). A port that is free now avoids the failed bind altogether.
        """
        current = int(getattr(backend, "_port", 49674))
        for port in range(current + 1, current + 200):
            probe = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            try:
                probe.bind(("127.0.0.1", port))
            except OSError:
                continue
            finally:
                probe.close()
            backend._port = port
            self.log(f"slice will listen on port {port} (was {current})")
            return

    def _processed(self) -> bool:
        gcode = self.gcode_list()
        return bool(gcode) and MARKER in gcode[0]

    def _do_wait_processed(self, action):
        started = time.time()
        if action.get("expect", True):
            yield self.wait_until(self._processed, action.get("timeout_s", 120), "the plugin's processing")
            self.record(action.get("record", "processing_wait_s"), round(time.time() - started, 2))
        else:
            yield float(action.get("settle_s", 3.0))
            if self._processed():
                raise RuntimeError("the G-code was processed although the setting is off")

    def _do_save(self, action):
        from UM.Mesh.MeshWriter import MeshWriter
        from UM.PluginRegistry import PluginRegistry

        path = action["path"]
        device = self.app.getOutputDeviceManager().getOutputDevice("local_file")
        writer = PluginRegistry.getInstance().getPluginObject("GCodeWriter")
        if device is None or writer is None:
            raise RuntimeError("Cura has no local-file output device or no GCodeWriter")
        started = time.time()
        device.writeStarted.emit(device)
        temp = path + ".part"
        with open(temp, "w", encoding="utf-8") as stream:
            ok = writer.write(stream, self.nodes(), MeshWriter.OutputMode.TextMode)
        device.writeFinished.emit(device)
        if not ok:
            raise RuntimeError(f"GCodeWriter failed: {writer.getInformation()}")
        os.replace(temp, path)
        self.record(action.get("record", "save_s"), round(time.time() - started, 2))
        self.log(f"wrote {path} ({os.path.getsize(path)} bytes)")

    def _do_dump_unprocessed(self, action):
        extension = self.extension()
        job = getattr(extension, "_job", None) if extension is not None else None
        if job is None:
            raise RuntimeError("the plugin has not processed a slice")
        with open(action["path"], "w", encoding="utf-8") as stream:
            stream.write("".join(job.layers_in))

    def _do_dump_engine_gcode(self, action):
        yield 0.2  # the copy is taken one event-loop turn after Done
        if self._engine_gcode is None:
            raise RuntimeError("no slice has finished yet")
        with open(action["path"], "w", encoding="utf-8") as stream:
            stream.write(self._engine_gcode)

    def _do_inspect(self, action):
        key = action.get("key", "delaunay_infill_enabled")
        stack = self.app.getGlobalContainerStack()
        found = stack.definition.findDefinitions(key=key)
        info = {"defined": bool(found)}
        if found:
            definition = found[0]
            ancestor = definition
            while ancestor.parent is not None:
                ancestor = ancestor.parent
            info.update(
                category=ancestor.key,
                parent=definition.parent.key if definition.parent is not None else None,
                label=definition.label,
                type=definition.type,
                settable_per_mesh=bool(definition.settable_per_mesh),
                siblings=[child.key for child in (definition.parent.children if definition.parent else [])],
            )
        visible = (self.app.getPreferences().getValue("general/visible_settings") or "").split(";")
        info["visible"] = key in visible
        info["value"] = stack.getProperty(key, "value")
        info["enabled"] = stack.getProperty(key, "enabled")
        self.record(f"inspect:{key}", info)

    def _do_resolve(self, action):
        stack = self.node(action["model"]).callDecoration("getStack") if action.get("model") else None
        stack = stack or self.app.getGlobalContainerStack()
        values = {key: stack.getProperty(key, "value") for key in action.get("keys", [])}
        self.record(action.get("record", "resolved"), values)

    def _do_stage(self, action):
        self.app.getController().setActiveStage(action.get("name", "PreviewStage"))
        yield float(action.get("settle_s", 1.0))

    def _do_camera(self, action):
        from UM.Math.Vector import Vector

        camera = self.app.getController().getScene().getActiveCamera()
        camera.setPosition(Vector(*action.get("position", [0, 300, 300])))
        camera.lookAt(Vector(*action.get("look_at", [0, 0, 0])))
        yield float(action.get("settle_s", 0.5))

    def _do_layer(self, action):
        from UM.PluginRegistry import PluginRegistry

        view = PluginRegistry.getInstance().getPluginObject("SimulationView")
        yield self.wait_until(lambda: view.getMaxLayers() > 0, 60, "the layer view's data")
        view.setLayer(min(int(action["layer"]), view.getMaxLayers()))
        yield float(action.get("settle_s", 1.0))

    def _do_expect_reslice(self, action):
        yield float(action.get("settle_s", 1.0))
        backend = self.app.getBackend()
        state = getattr(backend, "_backend_state", None)
        state = int(state) if state is not None else None
        left_done = any(s != 3 for s in self._backend_states)
        self.record(action.get("record", "reslice_after_change"), {"states": list(self._backend_states),
                                                                     "state_now": state})
        if not left_done:
            raise RuntimeError(f"the settings change did not invalidate the slice (states {self._backend_states})")

    def _do_sleep(self, action):
        yield float(action.get("s", 1.0))

    def _do_screenshot(self, action):
        yield float(action.get("delay_s", 2.0))  # let QML finish painting
        path = action["path"]
        command = [action.get("import", "/usr/bin/import"), "-window", "root", path]
        result = subprocess.run(command, capture_output=True, text=True, timeout=60, check=False)
        if result.returncode != 0 or not os.path.exists(path):
            raise RuntimeError(f"screenshot failed: {result.stderr.strip()}")
        self.log(f"screenshot {path}")

    def _do_step(self, action):
        path = action["file"]
        spec = importlib.util.spec_from_file_location(
            "delaunay_gui_step_" + os.path.splitext(os.path.basename(path))[0], path
        )
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        function = getattr(module, action["function"])
        return function(self, **action.get("args", {}))
