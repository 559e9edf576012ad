// Paint mode of the Density regions tool panel for Cura 5.x (Qt 6): paint density sets on the
// model's faces. Included by DensityRegionsPanel.qml; talks to DelaunayInfill/cura/paint_tool.py
// through UM.ActiveTool (the same properties and actions as the Qt 5 section).
import QtQuick 2.15
import QtQuick.Controls 2.15
import QtQuick.Layouts 1.15
import QtQuick.Dialogs

import UM 1.5 as UM
import Cura 1.0 as Cura

Column
{
    id: paintSection
    objectName: "paintSection"
    spacing: UM.Theme.getSize("default_margin").height

    readonly property var sets: UM.ActiveTool.properties.getValue("PaintSets") || []
    readonly property string mode: UM.ActiveTool.properties.getValue("PaintMode") || "place"
    readonly property int activeSet: UM.ActiveTool.properties.getValue("ActivePaintSet") || 0
    readonly property var modes: ["place", "paint", "erase"]
    readonly property real margin: UM.Theme.getSize("default_margin").width
    readonly property real controlHeight: UM.Theme.getSize("setting_control").height
    readonly property real third: Math.floor((width - 2 * margin) / 3)

    function fmt(value)
    {
        if (value === undefined || value === null || isNaN(value)) { return "" }
        return Number(value).toFixed(1).replace(/\.0$/, "")
    }

    UM.I18nCatalog { id: catalog; name: "cura" }  // Cura.ComboBox reads its empty-list text from `catalog`

    ListModel
    {
        id: modeModel
        ListElement { text: "Place regions" }  // a click places a region (the section above)
        ListElement { text: "Paint" }
        ListElement { text: "Erase" }
    }

    // ---- mode and brush; the next set's density and depth ----
    RowLayout
    {
        objectName: "paintModeRow"
        width: parent.width
        spacing: Math.round(paintSection.margin / 2)

        Cura.ComboBox
        {
            objectName: "paintMode"
            Layout.preferredWidth: Math.floor(paintSection.third * 1.25)
            Layout.preferredHeight: paintSection.controlHeight
            model: modeModel
            textRole: "text"
            currentIndex: Math.max(0, paintSection.modes.indexOf(paintSection.mode))
            onActivated: function(index) { UM.ActiveTool.setProperty("PaintMode", paintSection.modes[index]) }
        }
        UM.Label { text: "Brush"; elide: Text.ElideRight; Layout.fillWidth: true; horizontalAlignment: Text.AlignRight }
        Cura.TextField
        {
            objectName: "brushSize"
            Layout.preferredWidth: Math.floor(paintSection.third * 0.6)
            text: fmt(UM.ActiveTool.properties.getValue("BrushSize"))
            validator: DoubleValidator { bottom: 0.2; top: 500; decimals: 2; notation: DoubleValidator.StandardNotation }
            onEditingFinished: UM.ActiveTool.setProperty("BrushSize", parseFloat(text))
        }
        UM.Label { text: "mm" }
    }

    RowLayout
    {
        objectName: "paintValuesRow"
        width: parent.width
        spacing: Math.round(paintSection.margin / 2)

        Cura.TextField
        {
            objectName: "paintDensity"
            Layout.preferredWidth: Math.floor(paintSection.third * 0.6)
            text: fmt(UM.ActiveTool.properties.getValue("PaintDensity"))
            validator: DoubleValidator { bottom: 0; top: 100; decimals: 2; notation: DoubleValidator.StandardNotation }
            onEditingFinished: UM.ActiveTool.setProperty("PaintDensity", parseFloat(text))
        }
        UM.Label { text: "%" }
        Cura.TextField
        {
            objectName: "paintDepth"
            Layout.preferredWidth: Math.floor(paintSection.third * 0.6)
            text: fmt(UM.ActiveTool.properties.getValue("PaintDepth"))
            validator: DoubleValidator { bottom: 0.1; top: 500; decimals: 2; notation: DoubleValidator.StandardNotation }
            onEditingFinished: UM.ActiveTool.setProperty("PaintDepth", parseFloat(text))
        }
        UM.Label { text: "mm deep"; elide: Text.ElideRight; Layout.fillWidth: true }
        Cura.SecondaryButton
        {
            objectName: "newPaintSet"
            text: "New set"
            tooltip: "The next stroke paints a new set with this density and depth"
            onClicked: UM.ActiveTool.triggerAction("newPaintSet")
        }
    }

    UM.Label
    {
        width: parent.width
        visible: paintSection.mode !== "place"
        text: paintSection.mode === "paint" ? (paintSection.activeSet > 0
                ? "Drag over the model to paint set P" + paintSection.activeSet + "."
                : "Drag over the model to paint a new set.")
            : paintSection.mode === "erase" ? "Drag over painted faces to erase them."
            : "Choose Paint to paint density sets on the model's faces."
        wrapMode: Text.WordWrap
        color: UM.Theme.getColor("text_inactive")
    }

    UM.Label
    {
        width: parent.width
        text: paintSection.sets.length > 0 ? "Painted sets (each reaches its depth under the faces)" : "Paint density on the model: nothing painted yet"
        wrapMode: Text.WordWrap
        font: UM.Theme.getFont("default_bold")
    }

    Column
    {
        id: paintList
        objectName: "paintList"
        width: parent.width
        spacing: UM.Theme.getSize("default_lining").height * 2

        Repeater
        {
            model: paintSection.sets
            delegate: Rectangle
            {
                objectName: "paintRow" + modelData.label
                width: paintList.width
                height: paintRow.height + UM.Theme.getSize("default_lining").height * 4
                color: modelData.active ? UM.Theme.getColor("setting_control_highlight") : "transparent"
                border.width: modelData.active ? UM.Theme.getSize("default_lining").width : 0
                border.color: UM.Theme.getColor("setting_control_border_highlight")

                RowLayout
                {
                    id: paintRow
                    readonly property real free: Math.max(0, width - swatch.Layout.preferredWidth - pctLabel.implicitWidth
                        - mmLabel.implicitWidth - facesLabel.Layout.preferredWidth - deleteArea.Layout.preferredWidth - 7 * spacing)
                    anchors.verticalCenter: parent.verticalCenter
                    anchors.left: parent.left
                    anchors.right: parent.right
                    anchors.leftMargin: UM.Theme.getSize("default_lining").width * 2
                    anchors.rightMargin: UM.Theme.getSize("default_lining").width * 2
                    spacing: Math.round(paintSection.margin / 2)

                    // the set's number in its overlay colour; a click makes it the set the next stroke paints
                    Rectangle
                    {
                        id: swatch
                        objectName: "paintNumber" + modelData.label
                        Layout.preferredWidth: Math.round(paintSection.controlHeight * 1.1)
                        Layout.preferredHeight: Math.round(paintSection.controlHeight * 0.9)
                        radius: height / 2
                        color: modelData.color
                        UM.Label
                        {
                            anchors.centerIn: parent
                            text: modelData.label
                            font: UM.Theme.getFont("default_bold")
                            color: "white"
                        }
                        MouseArea
                        {
                            anchors.fill: parent
                            onClicked: UM.ActiveTool.triggerActionWithData("selectPaintSet", modelData.number)
                        }
                    }
                    Cura.TextField
                    {
                        objectName: "paintDensityField" + modelData.label
                        Layout.preferredWidth: Math.floor(paintRow.free / 2)
                        text: fmt(modelData.density)
                        validator: DoubleValidator { bottom: 0; top: 100; decimals: 2; notation: DoubleValidator.StandardNotation }
                        onEditingFinished: UM.ActiveTool.triggerActionWithData("editPaintSet", {"number": modelData.number, "density": parseFloat(text)})
                    }
                    UM.Label { id: pctLabel; text: "%" }
                    Cura.TextField
                    {
                        objectName: "paintDepthField" + modelData.label
                        Layout.preferredWidth: Math.floor(paintRow.free / 2)
                        text: fmt(modelData.depth)
                        validator: DoubleValidator { bottom: 0.1; top: 500; decimals: 2; notation: DoubleValidator.StandardNotation }
                        onEditingFinished: UM.ActiveTool.triggerActionWithData("editPaintSet", {"number": modelData.number, "depth": parseFloat(text)})
                    }
                    UM.Label { id: mmLabel; text: "mm" }
                    UM.Label
                    {
                        id: facesLabel
                        Layout.preferredWidth: Math.round(paintSection.controlHeight * 1.6)
                        text: modelData.faces + " f"
                        elide: Text.ElideRight
                        color: UM.Theme.getColor("text_inactive")
                    }
                    UM.TooltipArea
                    {
                        id: deleteArea
                        Layout.preferredWidth: Math.round(paintSection.controlHeight * 0.7)
                        Layout.preferredHeight: Layout.preferredWidth
                        text: "Delete painted set " + modelData.label

                        UM.SimpleButton
                        {
                            objectName: "deletePaint" + modelData.label
                            anchors.fill: parent
                            iconSource: UM.Theme.getIcon("Cancel")
                            color: UM.Theme.getColor("setting_control_button")
                            hoverColor: UM.Theme.getColor("setting_control_button_hover")
                            onClicked: UM.ActiveTool.triggerActionWithData("removePaintSet", modelData.number)
                        }
                    }
                }
            }
        }
    }

    // ---- export for the command line (delaunay-infill process --paint MODEL.stl:FACES.json:PCT:DEPTH) ----
    // Export asks where to write MODEL.stl (a save dialog); FACES.json goes beside it as MODEL.faces.json.
    FileDialog
    {
        id: exportDialog
        objectName: "exportDialog"
        property int number: 0
        readonly property bool savesFile: fileMode === FileDialog.SaveFile  // a save dialog (read by the GUI test)
        title: "Export painted set P" + number + " for the command line (--paint)"
        fileMode: FileDialog.SaveFile
        currentFolder: UM.ActiveTool.properties.getValue("ExportFolder") || ""
        nameFilters: ["STL model (*.stl)"]
        defaultSuffix: "stl"
        onAccepted: UM.ActiveTool.triggerActionWithData("exportChosenPaintSet", {"number": number, "file": selectedFile.toString()})
    }

    RowLayout
    {
        width: parent.width
        spacing: paintSection.margin
        visible: paintSection.sets.length > 0
        Item { Layout.fillWidth: true; Layout.preferredHeight: 1 }
        Cura.SecondaryButton
        {
            objectName: "exportPaintSet"
            text: "Export..."
            tooltip: "Save the model as MODEL.stl and the highlighted set as MODEL.faces.json, for the command line's --paint"
            enabled: paintSection.activeSet > 0
            onClicked:
            {
                exportDialog.number = paintSection.activeSet
                exportDialog.open()
            }
        }
    }

    UM.Label
    {
        width: parent.width
        visible: text !== ""
        text: UM.ActiveTool.properties.getValue("PaintStatus") || ""
        wrapMode: Text.WrapAnywhere
        color: UM.Theme.getColor("text_inactive")
    }
}
