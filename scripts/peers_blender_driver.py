"""Run the peer harness's blender_cloth.py inside Blender and keep positions at chosen times.

    blender -b --factory-startup --python scripts/peers_blender_driver.py -- \
        --peers-dir DIR --save X.npz --times 0.5 1 1.5 2 -- <blender_cloth.py options>

blender_cloth.py runs unchanged (its own scene building, timing and RESULT
line); it steps with scene.frame_set, which fills the cloth's point cache.
Afterwards this driver sets the frames of the wanted times again, which reads
them back from that cache (no re-simulation: nothing is timed here), and
saves them in the harness's canonical vertex order with the lowest z of
every frame.  Used by scripts/bench_peers.py.
"""
import os
import runpy
import sys

import bpy
import numpy as np


def split_args(argv):
    rest = argv[argv.index("--") + 1:]
    second = rest.index("--") if "--" in rest else len(rest)
    own, peer = rest[:second], rest[second + 1:]
    opts = {"times": []}
    key = None
    for a in own:
        if a.startswith("--"):
            key = a[2:].replace("-", "_")
            if key != "times":
                opts[key] = None
        elif key == "times":
            opts["times"].append(float(a))
        else:
            opts[key] = a
    return opts, peer


def main():
    opts, peer = split_args(sys.argv)
    peers_dir = os.path.abspath(opts["peers_dir"])
    sys.path.insert(0, peers_dir)
    import scenes
    sys.argv = [sys.argv[0], "--"] + peer
    runpy.run_path(os.path.join(peers_dir, "blender_cloth.py"), run_name="__main__")

    scene_id = peer[peer.index("--scene") + 1]
    n = int(peer[peer.index("--n") + 1])
    fps = int(peer[peer.index("--fps") + 1]) if "--fps" in peer else 60
    scn = bpy.context.scene
    cloth = bpy.data.objects["Cloth"]
    co = np.empty(len(cloth.data.vertices) * 3)
    cloth.data.vertices.foreach_get("co", co)
    M = np.array(cloth.matrix_world)
    perm = scenes.canonical_order((co.reshape(-1, 3) @ M[:3, :3].T + M[:3, 3])[:, :2], scene_id, n)

    def positions(frame):
        scn.frame_set(frame)
        dg = bpy.context.evaluated_depsgraph_get()
        ev = cloth.evaluated_get(dg)
        buf = np.empty(len(ev.data.vertices) * 3)
        ev.data.vertices.foreach_get("co", buf)
        Mw = np.array(ev.matrix_world)
        return (buf.reshape(-1, 3) @ Mw[:3, :3].T + Mw[:3, 3])[perm]

    last = scn.frame_end
    final = positions(last)
    frames = [1 + int(round(t * fps)) for t in opts["times"]]
    P = np.stack([positions(f) for f in frames])
    lowest = np.array([positions(f)[:, 2].min() for f in range(1, last + 1)])
    # the cache read back must be the state the run ended in
    again = positions(last)
    np.savez(opts["save"], times=np.array(opts["times"]), positions=P, final=final,
             lowest=lowest, lowest_times=(np.arange(1, last + 1) - 1) / fps,
             cache_mismatch=float(np.abs(again - final).max()))


main()
