"""Runs inside Blender (blender -b --factory-startup -P cycles_scene.py -- PARAMS.json): builds
the peer scene of bench/peers/cycles_bench.py in Cycles and renders it to an EXR.

PARAMS.json: {"vdb", "grid", "extinction", "g", "sun_direction" (towards the sun),
"sun_irradiance" [r, g, b] (W m^-2 on a plane facing the sun), "sky_radiance" [r, g, b],
"camera": {"position", "look_at", "up", "fov_deg"}, "resolution" [w, h], "samples", "seed",
"bounces", "threads", "out" (EXR path), "stats" (JSON path)}.

Conventions, so that the two renderers see one scene:
- coordinates: the VDB's own world coordinates are used as Blender's, unrotated, and the camera
  is placed in them from position / look_at / up; Blender's z-up convention only matters for
  skies that vary with direction, and the sky here is constant;
- sun: a Sun lamp of angle 0 (a delta light) whose strength is the irradiance on a plane
  perpendicular to it, as in a cloudbake shot; its light travels along the lamp's -Z, so +Z is
  turned to the direction towards the sun;
- medium: albedo 1, so a Volume Scatter node alone: its density is sigma_s = sigma_t per world
  unit = extinction x the grid's value, its anisotropy the Henyey-Greenstein g;
- sky: the world's Background, colour = radiance, strength 1;
- film: box filter of one pixel (cloudbake jitters uniformly in the pixel), no clamping, no
  denoising, no adaptive sampling, so Cycles' estimate is unbiased apart from its ray marching.
"""
import json
import sys
import time

import bpy
from mathutils import Matrix, Vector


def params():
    argv = sys.argv[sys.argv.index("--") + 1:]
    with open(argv[0]) as f:
        return json.load(f)


def clear_scene():
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj, do_unlink=True)


def add_volume(p):
    bpy.ops.object.volume_import(filepath=p["vdb"], align="WORLD", location=(0, 0, 0))
    obj = bpy.context.active_object
    mat = bpy.data.materials.new("cloud")
    mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    nodes.clear()
    out = nodes.new("ShaderNodeOutputMaterial")
    scatter = nodes.new("ShaderNodeVolumeScatter")
    scatter.inputs["Color"].default_value = (1, 1, 1, 1)
    scatter.inputs["Anisotropy"].default_value = p["g"]
    attr = nodes.new("ShaderNodeAttribute")
    attr.attribute_name = p["grid"]
    mul = nodes.new("ShaderNodeMath")
    mul.operation = "MULTIPLY"
    mul.inputs[1].default_value = p["extinction"]
    links.new(attr.outputs["Fac"], mul.inputs[0])
    links.new(mul.outputs["Value"], scatter.inputs["Density"])
    links.new(scatter.outputs["Volume"], out.inputs["Volume"])
    obj.data.materials.append(mat)


def look_at_matrix(position, look_at, up):
    pos = Vector(position)
    f = (Vector(look_at) - pos).normalized()
    r = f.cross(Vector(up)).normalized()
    u = r.cross(f)
    # A Blender camera looks along its local -Z with +Y up.
    return Matrix(((r.x, u.x, -f.x, pos.x), (r.y, u.y, -f.y, pos.y), (r.z, u.z, -f.z, pos.z),
                   (0, 0, 0, 1)))


def add_camera(p, scene):
    cam = p["camera"]
    data = bpy.data.cameras.new("camera")
    data.sensor_fit = "HORIZONTAL"  # cloudbake's fov_deg is horizontal too
    data.angle_x = cam["fov_deg"] * 3.141592653589793 / 180
    data.clip_start = 1e-3
    data.clip_end = 1e7
    obj = bpy.data.objects.new("camera", data)
    scene.collection.objects.link(obj)
    obj.matrix_world = look_at_matrix(cam["position"], cam["look_at"], cam["up"])
    scene.camera = obj


def add_sun(p, scene):
    e = p["sun_irradiance"]
    strength = max(e)
    data = bpy.data.lights.new("sun", type="SUN")
    data.energy = strength
    data.color = tuple(c / strength for c in e) if strength > 0 else (1, 1, 1)
    data.angle = 0.0
    obj = bpy.data.objects.new("sun", data)
    scene.collection.objects.link(obj)
    z = Vector(p["sun_direction"]).normalized()
    obj.rotation_euler = z.to_track_quat("Z", "Y").to_euler()


def set_world(p, scene):
    world = bpy.data.worlds.new("sky")
    world.use_nodes = True
    bg = world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = tuple(p["sky_radiance"]) + (1,)
    bg.inputs["Strength"].default_value = 1.0
    scene.world = world


def set_render(p, scene):
    scene.render.engine = "CYCLES"
    c = scene.cycles
    c.device = "CPU"
    c.samples = p["samples"]
    c.seed = p["seed"]
    c.use_adaptive_sampling = False
    c.use_denoising = False
    c.sample_clamp_direct = 0
    c.sample_clamp_indirect = 0
    c.max_bounces = p["bounces"]
    c.volume_bounces = p["bounces"]
    c.transparent_max_bounces = p["bounces"]
    c.pixel_filter_type = "BOX"
    c.filter_width = 1.0
    scene.render.threads_mode = "FIXED"
    scene.render.threads = p["threads"]
    scene.render.resolution_x, scene.render.resolution_y = p["resolution"]
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = False
    scene.view_settings.view_transform = "Standard"
    settings = scene.render.image_settings
    settings.file_format = "OPEN_EXR"
    settings.color_depth = "32"
    settings.color_mode = "RGBA"
    settings.exr_codec = "ZIP"
    scene.render.filepath = p["out"]


def main():
    p = params()
    clear_scene()
    scene = bpy.context.scene
    add_volume(p)
    add_camera(p, scene)
    add_sun(p, scene)
    set_world(p, scene)
    set_render(p, scene)
    t0 = time.time()
    bpy.ops.render.render(write_still=True)
    seconds = time.time() - t0
    with open(p["stats"], "w") as f:
        json.dump({"seconds": seconds, "samples": p["samples"],
                   "blender": bpy.app.version_string}, f)


main()
