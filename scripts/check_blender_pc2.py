"""Check a `distcloth export --format pc2` in Blender itself: the rest OBJ
imported as the README says keeps the vertex order, and the Mesh Cache
modifier reproduces every frame of the result file.

Not part of the test suite (Blender is not installed by scripts/setup.sh):

    .venv/bin/distcloth export RESULT.h5 --format pc2 --output /tmp/c.pc2
    .venv/bin/python -c "import h5py, numpy as np; f = h5py.File('RESULT.h5'); \\
        np.save('/tmp/c.npy', f['frames/positions'][:f.attrs['frames_written']])"
    blender -b --factory-startup --python scripts/check_blender_pc2.py -- /tmp/c.pc2 /tmp/c.npy

Prints the largest distance between Blender's evaluated mesh and the frame,
per frame, and exits 1 if one exceeds float32 rounding.
"""
import sys

import bpy
import numpy as np

cache, frames_npy = sys.argv[sys.argv.index("--") + 1:][:2]
frames = np.load(frames_npy)
for obj in list(bpy.data.objects):
    bpy.data.objects.remove(obj)
bpy.ops.wm.obj_import(filepath=cache[:-4] + "_rest.obj", forward_axis="Y", up_axis="Z")
obj = bpy.context.selected_objects[0]
mod = obj.modifiers.new("distcloth", "MESH_CACHE")
mod.cache_format = "PC2"
mod.filepath = cache
mod.frame_start = 1.0          # sample 0 at the scene's first frame
print(f"rest mesh: {len(obj.data.vertices)} vertices, {len(obj.data.uv_layers)} UV layers")
worst = 0.0
for k in range(frames.shape[0]):
    bpy.context.scene.frame_set(1 + k)
    evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    mesh = evaluated.to_mesh()
    co = np.array([v.co[:] for v in mesh.vertices])
    evaluated.to_mesh_clear()
    err = float(np.abs(co - frames[k]).max())
    worst = max(worst, err)
    print(f"frame {k}: max |Blender - result| = {err:.3g} m")
scale = float(np.abs(frames).max())
print(f"worst {worst:.3g} m ({'ok' if worst <= 1e-6 * max(scale, 1.0) else 'MISMATCH'})")
sys.exit(0 if worst <= 1e-6 * max(scale, 1.0) else 1)
