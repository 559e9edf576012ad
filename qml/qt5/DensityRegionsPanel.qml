// Density regions tool panel for Cura 4.x (Qt 5.15, QtQuick.Controls 2).
// Talks to DelaunayInfill/cura/region_tool.py through UM.ActiveTool.
//
// Cura's own styled controls (Cura.ComboBox, Cura.TextField, Cura.SecondaryButton,
// UM.SimpleButton), the same ones as in the Qt 6 panel; Uranium 4.13 has no UM.Label, so
// labels are Qt's with the theme's font and colour. Every row is a layout as wide as the
// panel whose fields share what the fixed parts leave, so nothing sticks out at Cura's
// default font or a larger one.
import QtQuick 2.15
import QtQuick.Controls 2.15
import QtQuick.Layouts 1.15

import UM 1.2 as UM
import Cura 1.0 as Cura

Item
{
    id: base
    objectName: "densityRegionsPanel"
    width: UM.Theme.getSize("setting_control").width * 2.8
    height: content.height

    readonly property var shapes: ["sphere", "cube", "cylinder"]
    readonly property var regions: UM.ActiveTool.properties.getValue("Regions") || []
    readonly property real baseDensity: UM.ActiveTool.properties.getValue("BaseDensity")
    readonly property bool delaunayEnabled: UM.ActiveTool.properties.getValue("DelaunayEnabled") === true
    readonly property real margin: UM.Theme.getSize("default_margin").width
    readonly property real controlHeight: UM.Theme.getSize("setting_control").height
    // Shares of the width left for a row's shape, size and density fields (explicit widths: a
    // layout's own shrinking ignores proportions)
    readonly property var shares: [0.44, 0.28, 0.28]
    readonly property real gridFree: width - 2 * margin

    function fmt(value)
    {
        if (value === undefined || value === null || isNaN(value)) { return "" }
        return Number(value).toFixed(1).replace(/\.0$/, "")
    }

    component PanelLabel: Label
    {
        font: UM.Theme.getFont("default")
        color: UM.Theme.getColor("text")
        renderType: Text.NativeRendering
    }

    UM.I18nCatalog { id: catalog; name: "cura" }  // Cura.ComboBox reads its empty-list text from `catalog`

    ListModel
    {
        id: shapeModel
        ListElement { text: "sphere" }
        ListElement { text: "cube" }
        ListElement { text: "cylinder" }
    }
    ListModel
    {
        id: meshModel  // a region made with Per Model Settings: its shape is its own mesh
        ListElement { text: "mesh" }
    }

    Column
    {
        id: content
        width: parent.width
        spacing: UM.Theme.getSize("default_margin").height

        PanelLabel
        {
            width: parent.width
            text: UM.ActiveTool.properties.getValue("ModelName") !== ""
                ? "<b>" + UM.ActiveTool.properties.getValue("ModelName") + "</b>: base density " + fmt(baseDensity) + " %"
                : "Select a model"
            textFormat: Text.StyledText
            elide: Text.ElideRight
        }

        PanelLabel
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
            objectName: "newRegionGrid"
            width: parent.width
            columns: 3
            columnSpacing: base.margin
            rowSpacing: UM.Theme.getSize("default_lining").height * 4

            PanelLabel { text: "Shape"; elide: Text.ElideRight; Layout.preferredWidth: Math.floor(base.gridFree * base.shares[0]) }
            PanelLabel { text: "Size (mm)"; elide: Text.ElideRight; Layout.preferredWidth: Math.floor(base.gridFree * base.shares[1]) }
            PanelLabel { text: "Density (%)"; elide: Text.ElideRight; Layout.preferredWidth: Math.floor(base.gridFree * base.shares[2]) }

            Cura.ComboBox
            {
                id: newShape
                objectName: "newShape"
                Layout.preferredWidth: Math.floor(base.gridFree * base.shares[0])
                Layout.preferredHeight: base.controlHeight
                model: shapeModel
                textRole: "text"
                currentIndex: Math.max(0, base.shapes.indexOf(UM.ActiveTool.properties.getValue("Shape")))
                onActivated: function(index) { UM.ActiveTool.setProperty("Shape", base.shapes[index]) }
            }
            Cura.TextField
            {
                id: newSize
                objectName: "newSize"
                Layout.preferredWidth: Math.floor(base.gridFree * base.shares[1])
                text: fmt(UM.ActiveTool.properties.getValue("Size"))
                validator: DoubleValidator { bottom: 0.5; top: 2000; decimals: 2; notation: DoubleValidator.StandardNotation }
                onEditingFinished: UM.ActiveTool.setProperty("Size", parseFloat(text))
            }
            Cura.TextField
            {
                id: newDensity
                objectName: "newDensity"
                Layout.preferredWidth: Math.floor(base.gridFree * base.shares[2])
                text: fmt(UM.ActiveTool.properties.getValue("Density"))
                validator: DoubleValidator { bottom: 0; top: 100; decimals: 2; notation: DoubleValidator.StandardNotation }
                onEditingFinished: UM.ActiveTool.setProperty("Density", parseFloat(text))
            }
        }

        RowLayout
        {
            width: parent.width
            spacing: base.margin

            PanelLabel
            {
                Layout.fillWidth: true
                text: "Click the model to place a region there, or add one at its centre."
                wrapMode: Text.WordWrap
                color: UM.Theme.getColor("text_inactive")
            }
            Cura.SecondaryButton
            {
                objectName: "addRegionButton"
                text: "Add"
                tooltip: "Add a region at the centre of the selected model"
                enabled: UM.ActiveTool.properties.getValue("ModelName") !== ""
                onClicked: UM.ActiveTool.triggerAction("addRegionAtCentre")
            }
        }

        // ---- the model's regions ----
        PanelLabel
        {
            width: parent.width
            text: regions.length > 0 ? "Regions (later ones win where they overlap)" : "No regions yet"
            wrapMode: Text.WordWrap
            font: UM.Theme.getFont("default_bold")
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
                    objectName: "regionRow" + modelData.label
                    width: regionList.width
                    height: row.height + UM.Theme.getSize("default_lining").height * 4
                    color: modelData.selected ? UM.Theme.getColor("setting_control_highlight") : "transparent"
                    border.width: modelData.selected ? UM.Theme.getSize("default_lining").width : 0
                    border.color: UM.Theme.getColor("setting_control_border_highlight")

                    RowLayout
                    {
                        id: row
                        // what the number, the units and the delete button leave for the three fields
                        readonly property real free: Math.max(0, width - number.Layout.preferredWidth - mmLabel.implicitWidth
                            - percentLabel.implicitWidth - deleteArea.Layout.preferredWidth - 6 * spacing)
                        anchors.verticalCenter: parent.verticalCenter
                        anchors.left: parent.left
                        anchors.right: parent.right
                        anchors.leftMargin: UM.Theme.getSize("default_lining").width * 2
                        anchors.rightMargin: UM.Theme.getSize("default_lining").width * 2
                        spacing: Math.round(base.margin / 2)

                        // The region's number; the scene node is named DelaunayRegion_<number>.
                        Rectangle
                        {
                            id: number
                            objectName: "regionNumber" + modelData.label
                            Layout.preferredWidth: Math.round(base.controlHeight * 0.9)
                            Layout.preferredHeight: Layout.preferredWidth
                            radius: width / 2
                            color: UM.Theme.getColor("primary")
                            PanelLabel
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
                        Cura.ComboBox
                        {
                            objectName: "shapeField" + modelData.label
                            Layout.preferredWidth: Math.floor(row.free * base.shares[0])
                            Layout.preferredHeight: base.controlHeight
                            enabled: modelData.own
                            model: modelData.own ? shapeModel : meshModel
                            textRole: "text"
                            currentIndex: modelData.own ? Math.max(0, base.shapes.indexOf(modelData.shape)) : 0
                            onActivated: function(index)
                            {
                                UM.ActiveTool.triggerActionWithData("editRegion", {"name": modelData.name, "shape": base.shapes[index]})
                            }
                        }
                        Cura.TextField
                        {
                            objectName: "sizeField" + modelData.label
                            Layout.preferredWidth: Math.floor(row.free * base.shares[1])
                            enabled: modelData.own
                            text: fmt(modelData.size)
                            validator: DoubleValidator { bottom: 0.5; top: 2000; decimals: 2; notation: DoubleValidator.StandardNotation }
                            onEditingFinished: UM.ActiveTool.triggerActionWithData("editRegion", {"name": modelData.name, "size": parseFloat(text)})
                        }
                        PanelLabel { id: mmLabel; text: "mm" }
                        Cura.TextField
                        {
                            objectName: "densityField" + modelData.label
                            Layout.preferredWidth: Math.floor(row.free * base.shares[2])
                            text: fmt(modelData.density)
                            validator: DoubleValidator { bottom: 0; top: 100; decimals: 2; notation: DoubleValidator.StandardNotation }
                            onEditingFinished: UM.ActiveTool.triggerActionWithData("editRegion", {"name": modelData.name, "density": parseFloat(text)})
                        }
                        PanelLabel { id: percentLabel; text: "%" }
                        UM.TooltipArea
                        {
                            id: deleteArea
                            Layout.preferredWidth: Math.round(base.controlHeight * 0.7)
                            Layout.preferredHeight: Layout.preferredWidth
                            text: "Delete " + modelData.name

                            UM.SimpleButton
                            {
                                objectName: "deleteRegion" + modelData.label
                                anchors.fill: parent
                                iconSource: UM.Theme.getIcon("Cancel")
                                color: UM.Theme.getColor("setting_control_button")
                                hoverColor: UM.Theme.getColor("setting_control_button_hover")
                                onClicked: UM.ActiveTool.triggerActionWithData("removeRegion", modelData.name)
                            }
                        }
                    }
                }
            }
        }

        // ---- border blending ----
        RowLayout
        {
            width: parent.width
            spacing: base.margin
            PanelLabel { text: "Feather borders (mm)"; elide: Text.ElideRight; wrapMode: Text.NoWrap; Layout.fillWidth: true }
            Cura.TextField
            {
                objectName: "featherField"
                Layout.preferredWidth: Math.floor(base.gridFree * base.shares[2])
                text: fmt(UM.ActiveTool.properties.getValue("Feather"))
                validator: DoubleValidator { bottom: 0; top: 100; decimals: 2; notation: DoubleValidator.StandardNotation }
                onEditingFinished: UM.ActiveTool.setProperty("Feather", parseFloat(text))
            }
        }

        // ---- paint density sets on the model's faces (PaintSection.qml, paint_tool.py) ----
        PaintSection { width: parent.width }
    }
}
