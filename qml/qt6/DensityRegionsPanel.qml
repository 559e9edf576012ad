// Density regions tool panel for Cura 5.x (Qt 6, QtQuick.Controls 2).
// Talks to DelaunayInfill/cura/region_tool.py through UM.ActiveTool.
import QtQuick 2.15
import QtQuick.Controls 2.15
import QtQuick.Layouts 1.15

import UM 1.5 as UM

Item
{
    id: base
    width: UM.Theme.getSize("setting_control").width * 2.4
    height: content.height

    readonly property var shapes: ["sphere", "cube", "cylinder"]
    readonly property var regions: UM.ActiveTool.properties.getValue("Regions") || []
    readonly property real baseDensity: UM.ActiveTool.properties.getValue("BaseDensity")
    readonly property bool delaunayEnabled: UM.ActiveTool.properties.getValue("DelaunayEnabled") === true
    readonly property real fieldWidth: Math.round(base.width * 0.2)
    readonly property real shapeWidth: Math.round(base.width * 0.3)

    function fmt(value)
    {
        if (value === undefined || value === null || isNaN(value)) { return "" }
        return Number(value).toFixed(1).replace(/\.0$/, "")
    }

    Column
    {
        id: content
        width: parent.width
        spacing: UM.Theme.getSize("default_margin").height

        UM.Label
        {
            width: parent.width
            text: UM.ActiveTool.properties.getValue("ModelName") !== ""
                ? "<b>" + UM.ActiveTool.properties.getValue("ModelName") + "</b>: base density " + fmt(baseDensity) + " %"
                : "Select a model"
            textFormat: Text.StyledText
            elide: Text.ElideRight
            font: UM.Theme.getFont("default")
            color: UM.Theme.getColor("text")
        }

        UM.Label
        {
            width: parent.width
            visible: !delaunayEnabled && UM.ActiveTool.properties.getValue("ModelName") !== ""
            text: "Delaunay variable infill is off for this model: regions print as Cura infill modifiers."
            wrapMode: Text.WordWrap
            font: UM.Theme.getFont("default_italic")
            color: UM.Theme.getColor("text_inactive")
        }

        // ---- the next region: shape, size, density ----
        GridLayout
        {
            columns: 4
            columnSpacing: UM.Theme.getSize("default_margin").width
            rowSpacing: UM.Theme.getSize("default_lining").height * 4

            UM.Label { text: "Shape"; font: UM.Theme.getFont("default"); color: UM.Theme.getColor("text") }
            UM.Label { text: "Size (mm)"; font: UM.Theme.getFont("default"); color: UM.Theme.getColor("text") }
            UM.Label { text: "Density (%)"; font: UM.Theme.getFont("default"); color: UM.Theme.getColor("text") }
            Item { width: 1; height: 1 }

            ComboBox
            {
                id: newShape
                objectName: "newShape"
                Layout.preferredWidth: base.shapeWidth
                model: base.shapes
                currentIndex: Math.max(0, base.shapes.indexOf(UM.ActiveTool.properties.getValue("Shape")))
                onActivated: UM.ActiveTool.setProperty("Shape", base.shapes[index])
            }
            TextField
            {
                id: newSize
                objectName: "newSize"
                Layout.preferredWidth: base.fieldWidth
                text: fmt(UM.ActiveTool.properties.getValue("Size"))
                validator: DoubleValidator { bottom: 0.5; top: 2000; decimals: 2; notation: DoubleValidator.StandardNotation }
                onEditingFinished: UM.ActiveTool.setProperty("Size", parseFloat(text))
            }
            TextField
            {
                id: newDensity
                objectName: "newDensity"
                Layout.preferredWidth: base.fieldWidth
                text: fmt(UM.ActiveTool.properties.getValue("Density"))
                validator: DoubleValidator { bottom: 0; top: 100; decimals: 2; notation: DoubleValidator.StandardNotation }
                onEditingFinished: UM.ActiveTool.setProperty("Density", parseFloat(text))
            }
            Button
            {
                objectName: "addRegionButton"
                text: "Add"
                ToolTip.visible: hovered
                ToolTip.text: "Add a region at the centre of the selected model"
                enabled: UM.ActiveTool.properties.getValue("ModelName") !== ""
                onClicked: UM.ActiveTool.triggerAction("addRegionAtCentre")
            }
        }

        UM.Label
        {
            width: parent.width
            text: "Click the model to place a region there."
            wrapMode: Text.WordWrap
            font: UM.Theme.getFont("default")
            color: UM.Theme.getColor("text_inactive")
        }

        // ---- the model's regions ----
        UM.Label
        {
            text: regions.length > 0 ? "Regions (later ones win where they overlap)" : "No regions yet"
            font: UM.Theme.getFont("default_bold")
            color: UM.Theme.getColor("text")
        }

        Column
        {
            id: regionList
            objectName: "regionList"
            width: parent.width
            spacing: UM.Theme.getSize("default_lining").height * 2

            Repeater
            {
                model: base.regions
                delegate: Rectangle
                {
                    width: regionList.width
                    height: row.height + UM.Theme.getSize("default_lining").height * 4
                    color: modelData.selected ? UM.Theme.getColor("setting_control_highlight") : "transparent"
                    border.width: modelData.selected ? UM.Theme.getSize("default_lining").width : 0
                    border.color: UM.Theme.getColor("setting_control_border_highlight")

                    RowLayout
                    {
                        id: row
                        anchors.verticalCenter: parent.verticalCenter
                        anchors.left: parent.left
                        anchors.leftMargin: UM.Theme.getSize("default_lining").width * 2
                        spacing: UM.Theme.getSize("default_margin").width / 2

                        // The region's number; the scene node is named DelaunayRegion_<number>.
                        Rectangle
                        {
                            objectName: "regionNumber" + modelData.label
                            width: UM.Theme.getSize("setting_control").height
                            height: width
                            radius: width / 2
                            color: UM.Theme.getColor("primary")
                            UM.Label
                            {
                                anchors.centerIn: parent
                                text: modelData.label
                                font: UM.Theme.getFont("default_bold")
                                color: UM.Theme.getColor("primary_text")
                            }
                            MouseArea
                            {
                                anchors.fill: parent
                                onClicked: UM.ActiveTool.triggerActionWithData("selectRegion", modelData.name)
                            }
                        }
                        ComboBox
                        {
                            objectName: "shapeField" + modelData.label
                            Layout.preferredWidth: base.shapeWidth
                            enabled: modelData.own
                            model: modelData.own ? base.shapes : ["mesh"]
                            currentIndex: modelData.own ? Math.max(0, base.shapes.indexOf(modelData.shape)) : 0
                            onActivated: UM.ActiveTool.triggerActionWithData("editRegion", {"name": modelData.name, "shape": base.shapes[index]})
                        }
                        TextField
                        {
                            objectName: "sizeField" + modelData.label
                            Layout.preferredWidth: Math.round(base.fieldWidth * 0.75)
                            enabled: modelData.own
                            text: fmt(modelData.size)
                            validator: DoubleValidator { bottom: 0.5; top: 2000; decimals: 2; notation: DoubleValidator.StandardNotation }
                            onEditingFinished: UM.ActiveTool.triggerActionWithData("editRegion", {"name": modelData.name, "size": parseFloat(text)})
                        }
                        UM.Label { text: "mm"; font: UM.Theme.getFont("default"); color: UM.Theme.getColor("text") }
                        TextField
                        {
                            objectName: "densityField" + modelData.label
                            Layout.preferredWidth: Math.round(base.fieldWidth * 0.75)
                            text: fmt(modelData.density)
                            validator: DoubleValidator { bottom: 0; top: 100; decimals: 2; notation: DoubleValidator.StandardNotation }
                            onEditingFinished: UM.ActiveTool.triggerActionWithData("editRegion", {"name": modelData.name, "density": parseFloat(text)})
                        }
                        UM.Label { text: "%"; font: UM.Theme.getFont("default"); color: UM.Theme.getColor("text") }
                        Button
                        {
                            objectName: "deleteRegion" + modelData.label
                            Layout.preferredWidth: UM.Theme.getSize("setting_control").height * 1.4
                            text: "\u2715"
                            ToolTip.visible: hovered
                            ToolTip.text: "Delete " + modelData.name
                            onClicked: UM.ActiveTool.triggerActionWithData("removeRegion", modelData.name)
                        }
                    }
                }
            }
        }

        // ---- border blending ----
        RowLayout
        {
            spacing: UM.Theme.getSize("default_margin").width
            UM.Label { text: "Feather borders (mm)"; font: UM.Theme.getFont("default"); color: UM.Theme.getColor("text") }
            TextField
            {
                objectName: "featherField"
                Layout.preferredWidth: Math.round(base.fieldWidth * 0.75)
                text: fmt(UM.ActiveTool.properties.getValue("Feather"))
                validator: DoubleValidator { bottom: 0; top: 100; decimals: 2; notation: DoubleValidator.StandardNotation }
                onEditingFinished: UM.ActiveTool.setProperty("Feather", parseFloat(text))
            }
        }
    }
}
