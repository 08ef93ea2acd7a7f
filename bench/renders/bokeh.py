"""A night street seen through a wide aperture: small lights out of focus become bokeh discs.

A string of small emitters of three sizes hangs 6-9 m away, far behind the plane of focus
(85 mm at f/1.2, focused at 3.5 m), so each becomes a disc about 13 pixels across. A sample
falls on a light through a small part of the lens only: the smallest lights are hit by a few
samples a pixel (their discs look like fireflies sample by sample, yet they are real light that
both halves share), the largest by many. A wet, glossy ground reflects them (more discs, and
fireflies where diffuse paths find a light through the gloss). In focus stand a pale statue and
a box lit by a warm lamp; a dim sky keeps the rest from black.
"""
import math

import bpy

from cycles_setup import box, material, sphere


def emitter(name, color, strength):
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    nodes = m.node_tree.nodes
    nodes.remove(nodes["Principled BSDF"])
    e = nodes.new("ShaderNodeEmission")
    e.inputs["Color"].default_value = (*color, 1)
    e.inputs["Strength"].default_value = strength
    m.node_tree.links.new(e.outputs[0], nodes["Material Output"].inputs["Surface"])
    return m


def build(scene):
    c = scene.cycles
    c.max_bounces, c.diffuse_bounces, c.glossy_bounces, c.transmission_bounces = 8, 3, 4, 8
    world = bpy.data.worlds.new("night")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs[0].default_value = (0.05, 0.08, 0.2, 1)
    world.node_tree.nodes["Background"].inputs[1].default_value = 0.05
    scene.world = world
    bpy.ops.mesh.primitive_plane_add(size=60, location=(0, 0, 0))
    bpy.context.object.data.materials.append(material("wet", (0.05, 0.05, 0.06), roughness=0.08))
    box((0, 12.0, 3.0), (30.0, 0.5, 6.0), material("facade", (0.3, 0.28, 0.25)))
    warm, cold = (1.0, 0.75, 0.45), (0.6, 0.8, 1.0)
    for i in range(15):
        x = -2.8 + 0.4 * i
        y = 6.0 + 3.0 * (i % 4) / 3.0
        z = 0.95 + 0.3 * math.sin(0.9 * i)
        radius = (0.008, 0.02, 0.045)[i % 3]
        sphere((x, y, z), radius, emitter("bulb%d" % i, warm if i % 2 else cold, 40.0))
    sphere((-0.2, 0.0, 0.22), 0.22, material("statue", (0.8, 0.78, 0.74), roughness=0.5))
    box((0.3, 0.2, 0.2), (0.25, 0.25, 0.4), material("box", (0.6, 0.25, 0.15), roughness=0.4))
    bpy.ops.object.light_add(type='POINT', location=(0.9, -1.2, 1.3))
    bpy.context.object.data.energy, bpy.context.object.data.shadow_soft_size = 60, 0.03
    bpy.context.object.data.color = warm
    return dict(location=(0.0, -3.5, 0.75), target=(0.0, 0.0, 0.45), lens=85, focus=3.5, fstop=1.2)
