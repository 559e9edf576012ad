"""Test-only Cura plugin: executes a JSON job inside a real Cura session (see driver.py)."""


def getMetaData():
    return {}


def register(app):
    from . import driver

    return {"extension": driver.GuiDriver()}
