"""Run the peer harness's newton_cloth.py (Warp + Newton) and keep positions at chosen times.

    out/peers/venv/bin/python scripts/peers_newton_driver.py --peers-dir DIR --save X.npz \
        --times 0.5 1 1.5 2 -- <newton_cloth.py options, with --runs 1>

newton_cloth.py runs unchanged (its scene building, warm-up, timing and
RESULT lines).  Two hooks watch it: newton.Model.state records the states
each build creates, and warp.capture_launch (one replay = one frame of the
timed run, the script's default graph mode) counts frames and copies the
positions at the wanted frames.  The copy happens inside the script's timed
frame; its cost (a (N, 3) float32 copy, microseconds, four times) is
measured and saved.  With an even number of substeps the replayed frame ends
in the first state of the build.  Used by scripts/bench_peers.py.
"""
import argparse
import os
import runpy
import sys
import time

import numpy as np


def main():
    argv = sys.argv[1:]
    cut = argv.index("--")
    p = argparse.ArgumentParser()
    p.add_argument("--peers-dir", required=True)
    p.add_argument("--save", required=True)
    p.add_argument("--times", type=float, nargs="+", required=True)
    a = p.parse_args(argv[:cut])
    peer = argv[cut + 1:]
    peers_dir = os.path.abspath(a.peers_dir)
    sys.path.insert(0, peers_dir)
    import newton
    import scenes
    import warp as wp

    fps = int(peer[peer.index("--fps") + 1]) if "--fps" in peer else 60
    scene_id = peer[peer.index("--scene") + 1]
    n = int(peer[peer.index("--n") + 1])
    wanted = {int(round(t * fps)): k for k, t in enumerate(a.times)}
    rec = {"states": [], "frame": 0, "saved": {}, "hook_s": 0.0, "rest": None}

    original_state = newton.Model.state

    def state(self, *args, **kwargs):
        s = original_state(self, *args, **kwargs)
        rec["states"].append(s)
        rec["frame"] = 0
        rec["rest"] = s.particle_q.numpy().astype(np.float64)    # a new build starts at rest
        return s

    original_launch = wp.capture_launch

    def capture_launch(graph, *args, **kwargs):
        out = original_launch(graph, *args, **kwargs)
        t0 = time.perf_counter()
        rec["frame"] += 1
        current = rec["states"][-2]            # the build's s0: see the module docstring
        if rec["frame"] in wanted:
            wp.synchronize()
            rec["saved"][wanted[rec["frame"]]] = current.particle_q.numpy().astype(np.float64)
        rec["hook_s"] += time.perf_counter() - t0
        return out

    newton.Model.state = state
    wp.capture_launch = capture_launch
    out_npy = os.path.splitext(a.save)[0] + "_final.npy"
    sys.argv = [os.path.join(peers_dir, "newton_cloth.py")] + peer + ["--out", out_npy]
    runpy.run_path(os.path.join(peers_dir, "newton_cloth.py"), run_name="__main__")

    assert len(rec["saved"]) == len(a.times), f"frames seen {rec['frame']}, saved {sorted(rec['saved'])}"
    # the build's own rest positions give the vertex order
    perm = scenes.canonical_order(rec["rest"][:, :2], scene_id, n)
    P = np.stack([rec["saved"][k] for k in range(len(a.times))])[:, perm]
    final = np.load(out_npy)            # the script's own export (canonical order)
    np.savez(a.save, times=np.array(a.times), positions=P, final=final, hook_s=rec["hook_s"],
             final_mismatch=float(np.abs(P[-1] - final).max()))


main()
