"""A sunlit exterior: five decades in one frame.

A sun and sky (Nishita) light a white wall with a doorway; the room behind it is lit only by
what comes through the door (dark, noisy, with fireflies). A glass sphere casts the sun's
caustic on the stone floor; a chrome sphere reflects the sun (a true highlight); a rough gold
sphere stands beside it.
"""
import math

import bpy

from cycles_setup import box, material, sphere


def build(scene):
    c = scene.cycles
    c.max_bounces, c.diffuse_bounces, c.glossy_bounces, c.transmission_bounces = 12, 4, 6, 12
    world = bpy.data.worlds.new("sky")
    world.use_nodes = True
    nt = world.node_tree
    sky = nt.nodes.new("ShaderNodeTexSky")
    sky.sky_type = 'NISHITA'
    sky.sun_elevation, sky.sun_rotation, sky.sun_size = math.radians(35), math.radians(200), math.radians(0.545)
    nt.links.new(sky.outputs[0], nt.nodes["Background"].inputs[0])
    nt.nodes["Background"].inputs[1].default_value = 0.2
    scene.world = world
    bpy.ops.mesh.primitive_plane_add(size=40, location=(0, 0, 0))
    bpy.context.object.data.materials.append(material("stone", (0.5, 0.45, 0.4), roughness=0.6))
    wall = material("wall", (0.8, 0.78, 0.7))
    for x in (-3.0, 3.0):
        box((x, 3.0, 1.75), (4.0, 0.3, 3.5), wall)
    box((0, 3.0, 3.0), (2.0, 0.3, 1.0), wall)  # the lintel
    room = material("room", (0.5, 0.5, 0.5))  # hollow: back, ceiling, sides
    box((0, 7.0, 1.75), (10.0, 0.2, 3.5), room)
    box((0, 5.1, 3.6), (10.0, 4.0, 0.2), room)
    for x in (-5.0, 5.0):
        box((x, 5.1, 1.75), (0.2, 4.0, 3.5), room)
    sphere((-1.4, 0.6, 0.7), 0.7, material("glass", (1, 1, 1), roughness=0.0, transmission=1.0))
    sphere((0.6, 0.0, 0.5), 0.5, material("chrome", (0.95, 0.95, 0.95), roughness=0.02, metallic=1.0))
    sphere((1.9, 1.0, 0.45), 0.45, material("gold", (1.0, 0.75, 0.35), roughness=0.25, metallic=1.0))
    return dict(location=(0.5, -6.5, 1.6), target=(0.0, 2.0, 1.2), lens=30)
