"""Cura adapters: the only part of DelaunayInfill that imports Cura, Uranium or Qt.

``extension`` (the after-slice pass, settings, messages), ``settings_injector``,
``snapshot`` (Cura's settings as plain data), ``adapter`` (plain data → the
G-code pass's settings), ``job`` (the background job); the density-region tool,
layer preview and estimates hook in through ``extension.addProcessedCallback``.
Nothing here is imported by the engine.
"""
