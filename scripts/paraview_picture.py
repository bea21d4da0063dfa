"""The README's ParaView picture: a result's last frame, the cloth coloured by
its strain field, the colliders in grey, read with the Xdmf3 Reader T.

    xvfb-run -a pvbatch scripts/paraview_picture.py RESULT.xdmf OUT.png

(pvbatch of Debian's ParaView needs an X display: xvfb-run gives it one.)
"""
import sys

from paraview import simple

path, out = sys.argv[1], sys.argv[2]
reader = simple.Xdmf3ReaderT(FileName=[path])
reader.UpdatePipelineInformation()
t_last = reader.TimestepValues[-1]
view = simple.GetActiveViewOrCreate("RenderView")
view.ViewSize = [960, 600]
view.ViewTime = t_last
view.OrientationAxesVisibility = 0
shown = simple.Show(reader, view)
shown.DiffuseColor = shown.AmbientColor = [0.62, 0.62, 0.66]   # the colliders: no strain
simple.ColorBy(shown, ("CELLS", "strain"))
lut = simple.GetColorTransferFunction("strain")
lut.ApplyPreset("Viridis (matplotlib)", True)
lut.RescaleTransferFunction(0.0, 0.04)
bar = simple.GetScalarBar(lut, view)
bar.Title = "strain (largest principal stretch - 1)"
bar.ComponentTitle = ""
shown.SetScalarBarVisibility(view, True)
simple.Render(view)               # the first render resets the camera: place it after
view.CameraPosition = [1.5, -1.8, 1.1]
view.CameraFocalPoint = [0.15, 0.0, 0.1]
view.CameraViewUp = [0.0, 0.0, 1.0]
view.CameraViewAngle = 30
simple.SaveScreenshot(out, view)
