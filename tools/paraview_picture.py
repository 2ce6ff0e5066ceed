"""Renders the last frame of an `sdem export --vtk DIR` with ParaView, offscreen: grains coloured
by mean stress (viridis), the contact network coloured by normal force, the box in black.

    pvbatch --force-offscreen-rendering tools/paraview_picture.py DIR OUT.png [SIZE]

(`pvbatch`/`pvpython` from Debian's or ParaView's own package; what it does is what the steps of
docs/visualisation.md do in the ParaView window.)
"""
import os
import sys

from paraview.simple import (ColorBy, GetColorTransferFunction, PVDReader, ResetCamera,
                             SaveScreenshot, Show, CreateView, Render)

d, out = sys.argv[1], sys.argv[2]
size = int(sys.argv[3]) if len(sys.argv) > 3 else 900

view = CreateView("RenderView")
view.ViewSize = [size, size]
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
bar = lut.GetScalarBar(view) if hasattr(lut, "GetScalarBar") else None
if bar is not None:
    bar.Title = "mean stress (compression +)"
    bar.ComponentTitle = ""
    bar.TitleColor = [0, 0, 0]
    bar.LabelColor = [0, 0, 0]

if os.path.exists(os.path.join(d, "contacts.pvd")):
    contacts = PVDReader(FileName=os.path.join(d, "contacts.pvd"))
    c = Show(contacts, view)
    ColorBy(c, ("CELLS", "normal_force"))
    flut = GetColorTransferFunction("normal_force")
    flut.ApplyPreset("Reds", True)
    c.RescaleTransferFunctionToDataRange(False, True)
    c.LineWidth = 2.0

boundary = PVDReader(FileName=os.path.join(d, "boundary.pvd"))
b = Show(boundary, view)
ColorBy(b, None)
b.AmbientColor = [0, 0, 0]
b.DiffuseColor = [0, 0, 0]
b.LineWidth = 3.0

view.InteractionMode = "2D"
ResetCamera(view)
view.CameraPosition = [view.CameraFocalPoint[0], view.CameraFocalPoint[1], 10.0]
view.CameraViewUp = [0, 1, 0]
ResetCamera(view)
Render(view)
SaveScreenshot(out, view, ImageResolution=[size, size], TransparentBackground=0)
print(f"{out}: time {last}")
