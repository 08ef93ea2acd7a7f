"""Renders a held-out scene as N one-sample renders with seeds first .. first + N - 1 (to be
split into two halves with variance by halves.py), or one reference render.

    blender -b -P bench/renders/make_render.py -- SCENE seeds FIRST N OUT_DIR
    blender -b -P bench/renders/make_render.py -- SCENE reference SPP OUT_DIR

SCENE is a module here (fog, exterior, bokeh) whose build(scene) makes the scene and returns the
camera. Seeds give OUT_DIR/seed_<i>.exr; the reference (seed 100000, SPP samples)
OUT_DIR/reference.exr. 400x300, two threads.
"""
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import bpy  # noqa: E402

from cycles_setup import camera, unbiased_cycles  # noqa: E402


def main():
    args = sys.argv[sys.argv.index("--") + 1:]
    name, mode = args[0], args[1]
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    unbiased_cycles(scene)
    scene.render.threads_mode, scene.render.threads = 'FIXED', 2
    camera(scene, **__import__(name).build(scene))
    if mode == "seeds":
        first, n, out = int(args[2]), int(args[3]), args[4]
        jobs = [(i, 1, os.path.join(out, "seed_%d.exr" % i)) for i in range(first, first + n)]
    else:
        jobs = [(100000, int(args[2]), os.path.join(args[3], "reference.exr"))]
    for seed, spp, path in jobs:
        scene.cycles.seed, scene.cycles.samples, scene.render.filepath = seed, spp, path
        start = time.time()
        bpy.ops.render.render(write_still=True)
        print("rendered %s in %.1f s" % (path, time.time() - start), flush=True)


main()
