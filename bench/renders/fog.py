"""A fog-filled room crossed by a spot beam: every pixel noisy, 90% of them dark.

The beam, seen through homogeneous fog (Principled Volume), comes from a high corner onto a
glossy floor panel beside a metal sphere; a glass sphere and a box stand in the fog; a dim
point lamp in the far corner keeps the rest of the room from black.
"""
import bpy

from cycles_setup import aim, box, material, sphere


def build(scene):
    c = scene.cycles
    c.max_bounces, c.diffuse_bounces, c.glossy_bounces = 8, 4, 4
    c.transmission_bounces, c.volume_bounces = 8, 2
    world = bpy.data.worlds.new("black")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs[1].default_value = 0.0
    scene.world = world
    box((0, 0, 2.5), (10, 10, 5), material("walls", (0.6, 0.6, 0.6)))  # seen from inside
    bpy.ops.mesh.primitive_plane_add(size=4, location=(1.0, 1.0, 0.01))
    bpy.context.object.data.materials.append(material("gloss", (0.8, 0.8, 0.8), roughness=0.05))
    sphere((0.8, 1.2, 0.6), 0.6, material("metal", (0.9, 0.8, 0.6), roughness=0.1, metallic=1.0))
    sphere((-1.5, 0.5, 0.5), 0.5, material("glass", (1, 1, 1), roughness=0.0, transmission=1.0))
    box((-0.5, 2.8, 0.6), (1.2, 1.2, 1.2), material("box", (0.7, 0.3, 0.2)))
    fog = material("fog", (1, 1, 1))
    nodes = fog.node_tree.nodes
    nodes.remove(nodes["Principled BSDF"])
    volume = nodes.new("ShaderNodeVolumePrincipled")
    volume.inputs["Density"].default_value = 0.06
    volume.inputs["Anisotropy"].default_value = 0.4
    fog.node_tree.links.new(volume.outputs[0], nodes["Material Output"].inputs["Volume"])
    box((0, 0, 2.5), (9.9, 9.9, 4.95), fog)
    bpy.ops.object.light_add(type='SPOT', location=(-4.0, -3.5, 4.6))
    spot = bpy.context.object
    spot.data.energy, spot.data.spot_size, spot.data.spot_blend = 4000, 0.2443, 0.2  # 14 degrees
    spot.data.shadow_soft_size = 0.05
    aim(spot, (0.8, 1.2, 0.0))
    bpy.ops.object.light_add(type='POINT', location=(3.5, 3.5, 4.5))
    bpy.context.object.data.energy, bpy.context.object.data.shadow_soft_size = 30, 0.05
    return dict(location=(3.8, -4.2, 1.7), target=(-0.5, 1.5, 1.0), lens=24)
