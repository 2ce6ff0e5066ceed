"""Renders the last frame of an `sdem export --vtk DIR` with ParaView, offscreen: grains coloured
by mean stress (viridis), the contact network coloured by normal force, the box in black.

    pvbatch --force-offscreen-rendering tools/paraview_picture.py DIR OUT.png [SIZE]

(`pvbatch`/`pvpython` from Debian's or ParaView's own package; what it does is what the steps of
docs/visualisation.md do in the ParaView window.)
"""
import os
import sys

from paraview.simple import (ColorBy, CreateView, GetColorTransferFunction,
                             GetOpacityTransferFunction, GetScalarBar,
                             PVDReader, Render, ResetCamera, SaveScreenshot, Show)

d, out = sys.argv[1], sys.argv[2]
size = int(sys.argv[3]) if len(sys.argv) > 3 else 900

view = CreateView("RenderView")
view.ViewSize = [int(1.25 * size), size]
view.OrientationAxesVisibility = 0
view.Background = [1, 1, 1]
try:  # ParaView >= 5.10 uses a palette unless told otherwise
    view.UseColorPaletteForBackground = 0
except AttributeError:
    pass

grains = PVDReader(FileName=os.path.join(d, "grains.pvd"))
last = grains.TimestepValues[-1] if grains.TimestepValues else 0.0
view.ViewTime = last

g = Show(grains, view)
g.Representation = "Surface With Edges"
g.EdgeColor = [0.15, 0.15, 0.15]
ColorBy(g, ("CELLS", "mean_stress_c"))
lut = GetColorTransferFunction("mean_stress_c")
lut.ApplyPreset("Viridis (matplotlib)", True)
g.RescaleTransferFunctionToDataRange(False, True)
g.SetScalarBarVisibility(view, True)


def style_bar(lut, title, position):
    bar = GetScalarBar(lut, view)
    bar.Title = title
    bar.ComponentTitle = ""
    bar.TitleColor = [0, 0, 0]
    bar.LabelColor = [0, 0, 0]
    bar.TitleFontSize = 14
    bar.LabelFontSize = 12
    bar.RangeLabelFormat = "%-#6.2g"
    bar.WindowLocation = "Any Location"
    bar.Position = position
    bar.ScalarBarLength = 0.4


style_bar(lut, "mean stress / E", [0.86, 0.52])

if os.path.exists(os.path.join(d, "contacts.pvd")):
    contacts = PVDReader(FileName=os.path.join(d, "contacts.pvd"))
    c = Show(contacts, view)
    ColorBy(c, ("CELLS", "normal_force"))
    flut = GetColorTransferFunction("normal_force")
    # Weak contacts transparent, strong ones black: the force chains over the grains.
    flut.ApplyPreset("Grayscale", True)
    flut.InvertTransferFunction()
    c.RescaleTransferFunctionToDataRange(False, True)
    flut.EnableOpacityMapping = 1
    top = flut.RGBPoints[-4]
    GetOpacityTransferFunction("normal_force").Points = [0.0, 0.0, 0.5, 0.0, top, 1.0, 0.5, 0.0]
    c.LineWidth = 2.0
    c.SetScalarBarVisibility(view, True)
    style_bar(flut, "normal force", [0.86, 0.06])

boundary = PVDReader(FileName=os.path.join(d, "boundary.pvd"))
b = Show(boundary, view)
b.ColorArrayName = ["CELLS", ""]
b.AmbientColor = [0, 0, 0]
b.DiffuseColor = [0, 0, 0]
b.LineWidth = 3.0

view.InteractionMode = "2D"
ResetCamera(view)
view.CameraPosition = [view.CameraFocalPoint[0], view.CameraFocalPoint[1], 10.0]
view.CameraViewUp = [0, 1, 0]
ResetCamera(view)
# The box fills the view, the colour bars at its right.
boundary.UpdatePipeline(last)
bounds = boundary.GetDataInformation().GetBounds()
print("box", bounds)
cx, cy = 0.5 * (bounds[0] + bounds[1]), 0.5 * (bounds[2] + bounds[3])
half = 0.5 * max(bounds[1] - bounds[0], bounds[3] - bounds[2])
view.CameraFocalPoint = [cx + 0.22 * half, cy, 0.0]
view.CameraPosition = [cx + 0.22 * half, cy, 10.0]
view.CameraParallelProjection = 1
view.CameraParallelScale = 1.04 * half
Render(view)
print("camera", view.CameraPosition, view.CameraFocalPoint, view.CameraParallelScale)
SaveScreenshot(out, view, ImageResolution=view.ViewSize, TransparentBackground=0)
print(f"{out}: time {last}")
