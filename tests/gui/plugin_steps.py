"""Step functions run inside Cura by the GUI driver (``{"do": "step", ...}``).

They check the plugin's hook for other parts (layer preview, estimates):
``extension.addProcessedCallback(callback)`` is called on the main thread
after every write-back with ``(plate, gcode_list, report)``.
"""

from __future__ import annotations

import threading


def watch_processed(ctx, record: str = "processed_calls"):
    """Register a callback that records each call it gets."""
    extension = ctx.extension()
    if extension is None:
        raise RuntimeError("the DelaunayInfill extension is not running")
    calls = []

    def on_processed(plate, gcode_list, report):
        scene = ctx.app.getController().getScene()
        calls.append({
            "plate": plate,
            "main_thread": threading.current_thread() is threading.main_thread(),
            "is_current_list": scene.gcode_dict.get(plate) is gcode_list,
            "marker_in_header": ";DELAUNAYINFILL_PROCESSED" in gcode_list[0],
            "layers_processed": getattr(report, "layers_processed", None),
            "failed_layers": list(getattr(report, "failed_layers", [])),
        })
        ctx.record(record, calls)

    ctx.watch_callback = on_processed  # keep it referenced for the session
    extension.addProcessedCallback(on_processed)
    ctx.record(record, calls)


def wait_for_calls(ctx, count: int = 1, record: str = "processed_calls", timeout_s: float = 60.0):
    """Wait until the callback of :func:`watch_processed` was called `count` times."""
    yield ctx.wait_until(lambda: len(ctx.status["records"].get(record, [])) >= count, timeout_s,
                         f"{count} processed-G-code callback(s)")


def break_pipeline(ctx, message: str = "test: the G-code pass is broken"):
    """Make the plugin's G-code pass raise, as a bug or bad input would."""
    import sys

    adapters = [m for n, m in sys.modules.items() if n.endswith("DelaunayInfill.cura.adapter")]
    if not adapters:
        raise RuntimeError("the plugin's adapter module is not loaded")
    adapter = adapters[0]
    ctx.saved_run_pipeline = adapter.run_pipeline

    def broken(*args, **kwargs):
        raise ValueError(message)

    adapter.run_pipeline = broken


def restore_pipeline(ctx):
    import sys

    for name, module in list(sys.modules.items()):
        if name.endswith("DelaunayInfill.cura.adapter"):
            module.run_pipeline = ctx.saved_run_pipeline


def wait_for_message(ctx, contains: str, record: str = "messages", timeout_s: float = 60.0):
    """Wait until Cura shows a message whose text contains `contains`; record all texts."""

    def shown():
        texts = [m.getText() for m in ctx.app.getVisibleMessages()]
        ctx.status["records"][record] = texts
        return any(contains in text for text in texts)

    yield ctx.wait_until(shown, timeout_s, f"a message containing {contains!r}")
    ctx.record(record, ctx.status["records"][record])


def start_without(ctx, module: str = "shapely.geometry", record: str = "dependency_messages"):
    """Run the plugin's start-up as a Cura without `module` would (Cura 5.0 has no shapely).

    ``sys.modules[name] = None`` makes ``import name`` raise ImportError; the
    extension must then show one message and connect nothing.
    """
    import sys

    extension = ctx.extension()
    saved = sys.modules.get(module)
    sys.modules[module] = None
    try:
        before = len(ctx.app.getVisibleMessages())
        extension._connect()
        texts = [m.getText() for m in ctx.app.getVisibleMessages()[before:]]
    finally:
        sys.modules[module] = saved
    ctx.record(record, texts)


def drop_package(ctx, path: str, record: str = "dropped_package"):
    """What dropping a .curapackage onto Cura's window does (Cura.qml's DropArea)."""
    try:
        from PyQt6.QtCore import QUrl
    except ImportError:
        from PyQt5.QtCore import QUrl

    package_id = ctx.app.installPackageViaDragAndDrop(QUrl.fromLocalFile(path).toString())
    ctx.record(record, package_id)
