"""Add the plugin's settings to Cura's Infill category ("Technique A").

The settings are data: ``delaunay_infill.def.json`` next to this module, in
Cura's own definition format.  Each machine definition that Cura loads is a
flattened tree, so the settings are grafted into every one of them when the
container registry reports it loaded (Cura 4.13 / SDK 7.9 and 5.x / SDK 8.x).

Uses Uranium internals (``_children``, ``_definition_cache``,
``_updateRelations``), as every plugin that adds settings this way does; all of
it is confined to this module.
"""

from __future__ import annotations

import collections
import json
import os

from UM.Logger import Logger
from UM.Settings.ContainerRegistry import ContainerRegistry
from UM.Settings.DefinitionContainer import DefinitionContainer
from UM.Settings.SettingDefinition import SettingDefinition

DEFINITION_FILE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "delaunay_infill.def.json")
CATEGORY_KEY = "infill"
#: Our settings go right after this one, so they sit near the top of Infill.
INSERT_AFTER_KEY = "infill_pattern"


def load_setting_definitions(path: str = DEFINITION_FILE) -> collections.OrderedDict:
    """The plugin's setting definitions (key -> definition dict), in file order."""
    with open(path, encoding="utf-8") as stream:
        return json.load(stream, object_pairs_hook=collections.OrderedDict)


def all_setting_keys(definitions: dict) -> list[str]:
    """Every key in `definitions`, children included, parents first."""
    keys: list[str] = []
    for key, body in definitions.items():
        keys.append(key)
        keys.extend(all_setting_keys(body.get("children", {})))
    return keys


class SettingsInjector:
    """Grafts the plugin's settings into each machine definition Cura loads.

    Keep the instance alive: Uranium signals hold weak references.
    """

    def __init__(self, definitions: collections.OrderedDict | None = None) -> None:
        self._definitions = definitions if definitions is not None else load_setting_definitions()
        self.keys = all_setting_keys(self._definitions)
        self._registry = ContainerRegistry.getInstance()
        self._registry.containerLoadComplete.connect(self._onContainerLoadComplete)

    def injectIntoLoaded(self) -> int:
        """Inject into machine definitions that were loaded before we connected.

        Returns
        -------
        int
            The number of definitions that received the settings.
        """
        count = 0
        # Metadata only: asking for the containers themselves would load all ~460 printers.
        for metadata in self._registry.findDefinitionContainersMetadata():
            container_id = metadata.get("id")
            if container_id and self._registry.isLoaded(container_id):
                containers = self._registry.findContainers(id=container_id)
                if containers and self._inject(containers[0]):
                    count += 1
        return count

    def _onContainerLoadComplete(self, container_id: str) -> None:
        # findContainers on an id that is not loaded yet would load it and
        # re-enter this handler forever.
        if not self._registry.isLoaded(container_id):
            return
        try:
            containers = self._registry.findContainers(id=container_id)
        except Exception:  # a broken container is Cura's business, not ours
            return
        if containers:
            self._inject(containers[0])

    def _inject(self, container) -> bool:
        if not isinstance(container, DefinitionContainer):
            return False
        if container.getMetaDataEntry("type") == "extruder":
            return False
        categories = container.findDefinitions(key=CATEGORY_KEY)
        if not categories:
            return False
        category = categories[0]
        first_key = next(iter(self._definitions))
        if any(child.key == first_key for child in category.children):
            return False  # already there (the registry reports some containers twice)
        try:
            position = self._insertPosition(category)
            for key, body in self._definitions.items():
                definition = SettingDefinition(key, container, category, None)
                definition.deserialize(body)
                category._children.insert(position, definition)
                position += 1
                self._addToCache(container, definition)
                container._updateRelations(definition)
            self._clearCaches(category)
        except Exception:
            Logger.logException("e", "DelaunayInfill: could not add settings to %s", container.getId())
            return False
        return True

    @staticmethod
    def _insertPosition(category) -> int:
        for index, child in enumerate(category.children):
            if child.key == INSERT_AFTER_KEY:
                return index + 1
        return len(category.children)

    def _addToCache(self, container, definition) -> None:
        container._definition_cache[definition.key] = definition
        for child in definition.children:
            self._addToCache(container, child)

    @staticmethod
    def _clearCaches(category) -> None:
        # Uranium >= 5.9 caches getAllKeys/getChild per instance; 4.13 has no such cache.
        try:
            from UM.Decorators import CachedMemberFunctions
        except ImportError:
            return
        try:
            CachedMemberFunctions.clearInstanceCache(category)
        except Exception:
            Logger.log("w", "DelaunayInfill: could not clear the setting definition cache")


def make_settings_visible(preferences, keys, marker_preference: str = "delaunay_infill/settings_made_visible") -> bool:
    """Append `keys` to the visible settings once per profile.

    Done once, so a user who hides the settings later keeps them hidden.

    Returns
    -------
    bool
        True when the visible-settings preference was changed.
    """
    # Registered first, unconditionally: asking Uranium for a preference nobody added logs
    # "Tried to get the value of non-existing setting" on every start. addPreference keeps a value
    # already read from cura.cfg (it only sets the default of a known preference).
    preferences.addPreference(marker_preference, False)
    if preferences.getValue(marker_preference):
        return False
    current = preferences.getValue("general/visible_settings") or ""
    if not current:
        # Cura fills an empty list from the active preset; ours alone would hide everything else.
        return False
    visible = [key for key in current.split(";") if key]
    missing = [key for key in keys if key not in visible]
    if missing:
        preferences.setValue("general/visible_settings", ";".join(visible + missing))
    preferences.setValue(marker_preference, True)
    return bool(missing)
