"""Blender (Cycles) set-up shared by the held-out scenes: unbiased settings and small helpers.

Every render must stay an unbiased estimate of the pixel, so the settings turn off what a
production render would use to hide fireflies: clamping, denoising, adaptive sampling.
"""

import bpy
import mathutils


def unbiased_cycles(scene, width=400, height=300):
    scene.render.engine = 'CYCLES'
    c = scene.cycles
    c.device = 'CPU'
    c.use_denoising = False
    c.use_adaptive_sampling = False
    c.sample_clamp_direct = 0.0  # Cycles clamps indirect light at 10 by default
    c.sample_clamp_indirect = 0.0
    c.caustics_reflective = True
    c.caustics_refractive = True
    c.use_animated_seed = False  # the seed is set per render
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    scene.render.use_persistent_data = True  # keep the scene loaded between renders
    scene.view_settings.view_transform = 'Standard'
    s = scene.render.image_settings
    s.file_format, s.color_mode, s.color_depth, s.exr_codec = 'OPEN_EXR', 'RGB', '32', 'ZIP'


def material(name, color, roughness=0.8, metallic=0.0, transmission=0.0):
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    p = m.node_tree.nodes["Principled BSDF"]
    p.inputs["Base Color"].default_value = (*color, 1)
    p.inputs["Roughness"].default_value = roughness
    p.inputs["Metallic"].default_value = metallic
    p.inputs["Transmission"].default_value = transmission
    return m


def box(location, scale, mat):
    bpy.ops.mesh.primitive_cube_add(size=1, location=location)
    o = bpy.context.object
    o.scale = scale
    o.data.materials.append(mat)
    return o


def sphere(location, radius, mat):
    bpy.ops.mesh.primitive_uv_sphere_add(radius=radius, location=location, segments=64, ring_count=32)
    bpy.ops.object.shade_smooth()
    bpy.context.object.data.materials.append(mat)
    return bpy.context.object


def aim(obj, target):
    """Points a camera or light (which look down their -Z) at target."""
    d = mathutils.Vector(target) - obj.location
    obj.rotation_euler = d.to_track_quat('-Z', 'Y').to_euler()


def camera(scene, location, target, lens, focus=None, fstop=None):
    """focus (metres) and fstop, when given, turn on depth of field (a thin lens)."""
    bpy.ops.object.camera_add(location=location)
    cam = bpy.context.object
    cam.data.lens = lens
    if focus is not None:
        cam.data.dof.use_dof = True
        cam.data.dof.focus_distance, cam.data.dof.aperture_fstop = focus, fstop
    aim(cam, target)
    scene.camera = cam
