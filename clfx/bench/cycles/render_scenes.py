"""Render the Cycles bench scenes (run with Blender's ``bpy``, Python 3.13; not part of clfx).

    python3.13 -m venv /work/bpy-venv && /work/bpy-venv/bin/pip install bpy
    nice /work/bpy-venv/bin/python clfx/bench/cycles/render_scenes.py [--out DIR]
        [--scenes spin,truck,...] [--samples 1024]

Every scene is 320x180, emission-only (no lights, no bounces: what a camera ray hits is what
the pixel shows), a 50 mm lens on a 36 mm sensor, frame 1 of a linear animation (positions
at frames 0, 1, 2 are keyed, so Blender's vector pass has both halves).  For each scene
``<name>`` the script writes into ``--out`` (default: ``data`` beside this file):

- ``<name>.sharp.exr``: the frame without motion blur, as Blender writes it
  (OPEN_EXR_MULTILAYER, half float, PIZ; pack.py keeps the same names, ZIP): ``ViewLayer.Combined.RGBA``, ``ViewLayer.Depth.Z``,
  ``ViewLayer.Vector.XYZW``, and the compositor's Vector Blur node of those passes
  (shutter 0.5, 32 samples) as ``Composite.Combined.RGBA``: Blender's own post-process
  motion blur, the peer row;
- ``<name>.truth1.exr``, ``<name>.truth2.exr``: the frame rendered with Cycles' motion blur
  (180 degree shutter centred on the frame), seeds 1 and 2 (RGB half, PIZ): the truth and
  its own noise floor.

The rolling-shutter scene (``truck_rolling``) is ``truck`` (whose sharp frame it shares) and
its truth is Cycles' rolling shutter (top row first, 0.75 of a frame from the frame time,
each row an instant: one render, ``truck_rolling.truth1.exr``).

The depth-of-field scenes (``dof_large``, :data:`DOF_SCENES`) are still frames through a
200 mm f/2 focused at 2 m: ``<name>.sharp.exr`` is the pinhole frame (depth of field off)
with ``ViewLayer.Depth.Z`` and Blender's compositor Defocus node of it (the same f-number and
focus, round bokeh) as ``Composite.Combined.RGBA``; the truths are Cycles' thin lens with the
aperture that gives clfx's circle of confusion (:func:`cycles_fstop`), seeds 1 and 2
(:data:`DOF_SAMPLES`: the lamps' bokeh is the noisiest part, 37.5 dB at 8192).
"""
from __future__ import annotations

import argparse
import math
import os
import random
import sys
import time

import bpy
import mathutils

W, H = 320, 180
FOCAL_MM, SENSOR_MM = 50.0, 36.0
F_PX = FOCAL_MM / SENSOR_MM * W          # 444.4 px


def px_m(depth: float, px: float, f_px: float = F_PX) -> float:
    """Metres spanned by ``px`` pixels at ``depth`` metres (at the frame centre) through a
    lens of focal length ``f_px`` pixels (default: the 50 mm)."""
    return px * depth / f_px


# The depth-of-field lens (clfx.bench.cycles.DOF_*): a 200 mm f/2 focused at 2 m (its
# close focus) on the 36 mm sensor: CoC diameter at infinity K = f^2 / (N (S - f)) = 11.1 mm,
# 98.8 px at 320 wide (radius 49.4 px).
DOF_FOCAL_MM, DOF_F_NUMBER, DOF_FOCUS_M = 200.0, 2.0, 2.0
DOF_F_PX = DOF_FOCAL_MM / SENSOR_MM * W  # 1777.8 px


def cycles_fstop(f_number: float, focal_mm: float, focus_m: float) -> float:
    """The ``aperture_fstop`` that gives Cycles' camera clfx's CoC for ``f_number``.

    Cycles' thin lens keeps the pinhole's framing and jitters the ray origin over an aperture
    of radius ``f / (2 N)`` aimed at the focus plane, so its CoC diameter at infinity is
    ``f^2 / (N S)`` on the sensor; clfx's (and Blender's Defocus node's) real thin lens has
    the image distance in it: ``f^2 / (N (S - f))``.  ``N (S - f) / S`` makes them equal
    (f/1.8 for f/2 at 200 mm and 2 m: the same f-number would give a CoC 10 % smaller).
    """
    s_mm = focus_m * 1000.0
    return f_number * (s_mm - focal_mm) / s_mm


# -- scene building ----------------------------------------------------------------------
def reset():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.render.resolution_x, scene.render.resolution_y = W, H
    scene.render.resolution_percentage = 100
    scene.cycles.max_bounces = 0
    scene.cycles.use_denoising = False
    scene.cycles.use_adaptive_sampling = False
    scene.cycles.use_animated_seed = False
    scene.render.film_transparent = False
    scene.frame_start, scene.frame_end = 0, 2
    scene.frame_set(1)
    world = bpy.data.worlds.new("world")
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.02, 0.025, 0.035, 1)
    scene.world = world
    cam_data = bpy.data.cameras.new("cam")
    cam_data.lens, cam_data.sensor_width, cam_data.sensor_fit = FOCAL_MM, SENSOR_MM, "HORIZONTAL"
    cam_data.clip_start, cam_data.clip_end = 0.1, 1000.0
    cam = bpy.data.objects.new("cam", cam_data)
    scene.collection.objects.link(cam)
    scene.camera = cam
    cam.location = (0.0, 0.0, 0.0)
    cam.rotation_euler = (math.radians(90.0), 0.0, 0.0)     # looks along +Y, up +Z
    return scene, cam


def emission(name, texture, colour_a, colour_b, scale=1.0, strength=1.0):
    """An emission material whose colour is ``texture`` ('flat', 'checker', 'brick',
    'stripes', 'noise') between two colours, in the object's own coordinates."""
    mat = bpy.data.materials.new(name)
    nt = mat.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    em = nt.nodes.new("ShaderNodeEmission")
    em.inputs["Strength"].default_value = strength
    nt.links.new(em.outputs["Emission"], out.inputs["Surface"])
    if texture == "flat":
        em.inputs["Color"].default_value = (*colour_a, 1)
        return mat
    coord = nt.nodes.new("ShaderNodeTexCoord")
    if texture in ("checker", "brick"):
        tex = nt.nodes.new("ShaderNodeTexChecker" if texture == "checker" else "ShaderNodeTexBrick")
        tex.inputs["Color1"].default_value = (*colour_a, 1)
        tex.inputs["Color2"].default_value = (*colour_b, 1)
        if texture == "brick":
            tex.inputs["Mortar"].default_value = (0.02, 0.02, 0.02, 1)
        tex.inputs["Scale"].default_value = scale
        nt.links.new(coord.outputs["Object"], tex.inputs["Vector"])
        nt.links.new(tex.outputs["Color"], em.inputs["Color"])
        return mat
    if texture == "stripes":
        tex = nt.nodes.new("ShaderNodeTexWave")
        tex.wave_type, tex.bands_direction = "BANDS", "X"
        tex.inputs["Scale"].default_value = scale
        tex.inputs["Distortion"].default_value = 0.0
        nt.links.new(coord.outputs["Object"], tex.inputs["Vector"])
    else:   # noise
        tex = nt.nodes.new("ShaderNodeTexNoise")
        tex.inputs["Scale"].default_value = scale
        tex.inputs["Detail"].default_value = 6.0
        nt.links.new(coord.outputs["Object"], tex.inputs["Vector"])
    ramp = nt.nodes.new("ShaderNodeValToRGB")
    ramp.color_ramp.elements[0].color = (*colour_a, 1)
    ramp.color_ramp.elements[1].color = (*colour_b, 1)
    if texture == "stripes":      # sharp-edged stripes
        ramp.color_ramp.elements[0].position = 0.49
        ramp.color_ramp.elements[1].position = 0.51
    else:
        ramp.color_ramp.elements[0].position = 0.3
        ramp.color_ramp.elements[1].position = 0.7
    nt.links.new(tex.outputs["Fac"], ramp.inputs["Fac"])
    nt.links.new(ramp.outputs["Color"], em.inputs["Color"])
    return mat


def add(scene, kind, name, material, location, size, rotation=(0.0, 0.0, 0.0)):
    """A mesh ('plane' facing the camera, 'disk' facing the camera, 'cube', 'sphere');
    ``size`` (x, y, z) in world axes (y: along the view), ``rotation`` Euler XYZ (a rotation
    about Y turns a plane or disk in the image plane)."""
    if kind == "plane":
        bpy.ops.mesh.primitive_plane_add(size=1.0)
    elif kind == "disk":
        bpy.ops.mesh.primitive_cylinder_add(vertices=96, radius=0.5, depth=0.02)
    elif kind == "cube":
        bpy.ops.mesh.primitive_cube_add(size=1.0)
    else:
        bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16, radius=0.5)
    obj = bpy.context.active_object
    obj.name = name
    size = size if isinstance(size, tuple) else (size, size, size)
    if kind == "disk":       # face the camera (axis along Y)
        obj.data.transform(mathutils.Matrix.Rotation(math.radians(90.0), 4, "X"))
    if kind == "plane":      # face the camera, keeping the texture's local x, y in the plane
        rotation = (rotation[0] + math.radians(90.0), rotation[1], rotation[2])
        size = (size[0], size[2], size[1])
    obj.scale = size
    obj.location = location
    obj.rotation_euler = rotation
    obj.data.materials.append(material)
    obj.cycles.motion_steps = 3     # rotation sampled finely enough to follow its arc
    return obj


def key(obj, frames):
    """Key ``obj`` at frames 0, 1, 2: ``frames`` = {frame: (location, rotation)}."""
    for f, (loc, rot) in frames.items():
        obj.location = loc
        obj.rotation_euler = rot
        obj.keyframe_insert("location", frame=f)
        obj.keyframe_insert("rotation_euler", frame=f)
    # Constant speed: Blender keys new points as Bezier (eased) whatever the preference says
    # in a background session, which moves 1.19x the keyed speed through frame 1 +- 0.25.
    ad = obj.animation_data
    for fc in ad.action.layers[0].strips[0].channelbag(ad.action_slot).fcurves:
        for kp in fc.keyframe_points:
            kp.interpolation = "LINEAR"


def linear(obj, velocity=(0.0, 0.0, 0.0), spin=(0.0, 0.0, 0.0)):
    """Animate ``obj`` from its frame-1 placement: ``velocity`` m/frame, ``spin`` rad/frame."""
    loc0, rot0 = tuple(obj.location), tuple(obj.rotation_euler)
    key(obj, {f: (tuple(l + v * (f - 1) for l, v in zip(loc0, velocity)),
                  tuple(r + s * (f - 1) for r, s in zip(rot0, spin))) for f in (0, 1, 2)})


def wall(scene, depth=20.0):
    wide = depth * SENSOR_MM / FOCAL_MM * 1.6
    mat = emission("wall", "brick", (0.55, 0.42, 0.3), (0.12, 0.14, 0.18), scale=10.0)
    return add(scene, "plane", "wall", mat, (0.0, depth, 0.0), (wide, 1.0, wide * 0.6))


# -- the scenes --------------------------------------------------------------------------
def scene_spin(scene, cam):
    """A checkered wheel spinning 72 deg/frame with a bright rim light, a propeller turning
    60 deg/frame the other way, and a box translating 40 px/frame."""
    wall(scene)
    d = 5.0
    r = px_m(d, 55.0)
    wheel = add(scene, "disk", "wheel", emission("wheel", "checker", (0.15, 0.45, 0.85),
                                                   (0.9, 0.88, 0.8), scale=6.0),
                (px_m(d, -75.0), d, px_m(d, 10.0)), (2 * r, 1.0, 2 * r))
    rim = add(scene, "sphere", "rim light", emission("rim", "flat", (1.0, 0.7, 0.35), None,
                                                        strength=40.0),
              (0.0, -0.02, 0.42), 0.06)
    rim.parent = wheel
    linear(wheel, spin=(0.0, math.radians(72.0), 0.0))
    dp = 3.5
    prop = add(scene, "plane", "propeller", emission("prop", "stripes", (0.85, 0.85, 0.8),
                                                      (0.08, 0.08, 0.1), scale=4.0),
               (px_m(dp, 70.0), dp, px_m(dp, -20.0)), (px_m(dp, 90.0), 1.0, px_m(dp, 12.0)))
    linear(prop, spin=(0.0, math.radians(-60.0), 0.0))
    db = 4.0
    box = add(scene, "cube", "box", emission("box", "checker", (0.8, 0.25, 0.1), (0.95, 0.85, 0.6),
                                             scale=2.5),
              (px_m(db, -10.0), db, px_m(db, 55.0)), px_m(db, 32.0),
              rotation=(0.3, 0.2, 0.5))
    linear(box, velocity=(px_m(db, 40.0), 0.0, 0.0))


def _posts(scene):
    """Posts and a ball at several depths over the far wall (for the camera moves)."""
    wall(scene)
    for i, (x, d, col) in enumerate(((-110.0, 2.5, (0.85, 0.8, 0.7)), (-20.0, 5.0, (0.3, 0.7, 0.4)),
                                     (60.0, 10.0, (0.7, 0.4, 0.8)), (130.0, 3.5, (0.9, 0.6, 0.2)))):
        add(scene, "plane", f"post {i}", emission(f"post{i}", "stripes", col, (0.06, 0.05, 0.05),
                                                   scale=1.0),
            (px_m(d, x), d, 0.0), (px_m(d, 22.0), 1.0, px_m(d, 260.0)))
    add(scene, "sphere", "ball", emission("ball", "checker", (0.9, 0.3, 0.15), (0.95, 0.9, 0.8),
                                          scale=4.0),
        (px_m(7.0, 20.0), 7.0, px_m(7.0, 45.0)), px_m(7.0, 50.0))
    add(scene, "sphere", "lamp", emission("lamp", "flat", (1.0, 0.85, 0.6), None, strength=30.0),
        (px_m(4.0, 95.0), 4.0, px_m(4.0, -55.0)), px_m(4.0, 4.0))


TRUCK_M = px_m(2.5, 40.0)
"""The truck's speed, m/frame: the nearest post (2.5 m) moves 40 px/frame."""


def scene_truck(scene, cam):
    """The camera trucking right (TRUCK_M m/frame) past posts at 2.5-10 m: parallax."""
    _posts(scene)
    linear(cam, velocity=(TRUCK_M, 0.0, 0.0))


PAN_DEG = 2.5
"""The pan's speed, degrees/frame (about 19 px/frame at the centre)."""


def scene_pan(scene, cam):
    """The camera panning right PAN_DEG deg/frame while trucking left half as fast as the
    truck: parallax in a pan."""
    _posts(scene)
    linear(cam, velocity=(-0.5 * TRUCK_M, 0.0, 0.0), spin=(0.0, 0.0, -math.radians(PAN_DEG)))


def scene_crossing(scene, cam):
    """A near card (3 m) moving right 36 px/frame over a far disk (8 m) moving left
    22 px/frame, crossing at the frame time, over the wall; a slow label with fine text-like
    blocks drifting 1.5 px/frame."""
    wall(scene)
    dfar, dnear = 8.0, 3.0
    disk = add(scene, "disk", "far disk", emission("far", "stripes", (0.9, 0.3, 0.1),
                                                    (0.95, 0.85, 0.6), scale=5.0),
               (px_m(dfar, 10.0), dfar, 0.0), px_m(dfar, 80.0), rotation=(0.0, 0.5, 0.0))
    linear(disk, velocity=(px_m(dfar, -22.0), 0.0, 0.0))
    card = add(scene, "plane", "near card", emission("near", "checker", (0.75, 0.75, 0.7),
                                                      (0.05, 0.06, 0.08), scale=4.0),
               (px_m(dnear, -15.0), dnear, px_m(dnear, -12.0)), (px_m(dnear, 60.0), 1.0,
                                                                 px_m(dnear, 45.0)))
    linear(card, velocity=(px_m(dnear, 36.0), 0.0, px_m(dnear, 4.0)))


def scene_slow(scene, cam):
    """Fine textures moving slowly: stripes ~3 px wide moving 2 px/frame, noise 1 px/frame
    diagonally, a checker of ~2 px squares 3 px/frame down."""
    wall(scene)
    d = 6.0
    a = add(scene, "plane", "stripes", emission("fine stripes", "stripes", (0.8, 0.78, 0.7),
                                                 (0.08, 0.08, 0.1), scale=10.0),
            (px_m(d, -80.0), d, 0.0), (px_m(d, 120.0), 1.0, px_m(d, 140.0)),
            rotation=(0.0, 0.3, 0.0))
    linear(a, velocity=(px_m(d, 2.0), 0.0, 0.0))
    b = add(scene, "plane", "grain", emission("grain", "noise", (0.1, 0.12, 0.1),
                                               (0.9, 0.8, 0.5), scale=40.0),
            (px_m(d, 40.0), d, px_m(d, 35.0)), (px_m(d, 90.0), 1.0, px_m(d, 70.0)))
    linear(b, velocity=(px_m(d, 0.7), 0.0, px_m(d, 0.7)))
    c = add(scene, "plane", "checker", emission("fine checker", "checker", (0.85, 0.85, 0.85),
                                                 (0.05, 0.05, 0.05), scale=28.0),
            (px_m(d, 110.0), d, px_m(d, -40.0)), (px_m(d, 70.0), 1.0, px_m(d, 60.0)),
            rotation=(0.0, 0.2, 0.0))
    linear(c, velocity=(0.0, 0.0, px_m(d, -3.0)))


DOF_LARGE = {   # name: depth m, centre x, y (px from the frame centre, y down), w, h px, turn deg
    "sign": (5.0, 90.0, -40.0, 96.0, 54.0, 30.0),
    "subject": (DOF_FOCUS_M, -16.0, 9.0, 96.0, 108.0, 6.0),
    "near post": (1.1, -64.0, 0.0, 22.0, 216.0, 0.0),
    "rail": (1.3, 32.0, 63.0, 288.0, 11.0, 0.0),
}
"""What stands in front of ``dof_large``'s wall, in the pinhole frame."""


def _covered(x: float, y: float, margin: float) -> bool:
    """Whether the point (px from the frame centre, y down) lies within ``margin`` px of
    anything in front of ``dof_large``'s wall (a turn is clockwise on screen)."""
    for _, cx, cy, w, h, turn in DOF_LARGE.values():
        c, s = math.cos(math.radians(turn)), math.sin(math.radians(turn))
        u, v = (x - cx) * c + (y - cy) * s, -(x - cx) * s + (y - cy) * c
        if abs(u) <= 0.5 * w + margin and abs(v) <= 0.5 * h + margin:
            return True
    return False


def scene_dof_large(scene, cam):
    """Large circles of confusion over each other (the layered ``dof:large``'s set-up)
    through the 200 mm f/2 at 2 m: a brick wall at 12 m (CoC radius 41 px) with 16 small
    bright lamps on it (5-7 px wide: smaller ones need far more samples for the same noise
    floor; none hidden in the pinhole frame, which no input would show), a striped sign at
    5 m (30 px), an in-focus checkered subject at 2 m, a near post at 1.1 m (-40 px)
    crossing the subject and a rail at 1.3 m (-27 px) crossing all (:data:`DOF_LARGE`)."""
    f = DOF_F_PX
    cam.data.lens = DOF_FOCAL_MM
    dw = 12.0
    wide = dw * SENSOR_MM / DOF_FOCAL_MM * 1.6
    add(scene, "plane", "wall", emission("wall", "brick", (0.55, 0.42, 0.3), (0.12, 0.14, 0.18),
                                          scale=24.0, strength=0.3),
        (0.0, dw, 0.0), (wide, 1.0, wide * 0.6))
    rng = random.Random(17)
    lamps = 0
    while lamps < 16:
        x, y = rng.uniform(-150.0, 150.0), rng.uniform(-80.0, 80.0)
        if _covered(x, y, 6.0):
            continue
        v = math.exp(rng.uniform(math.log(6.0), math.log(80.0)))
        tint = [rng.uniform(0.4, 1.0) for _ in range(3)]
        tint = tuple(t / max(tint) for t in tint)
        d = dw - 0.05
        add(scene, "sphere", f"lamp {lamps}", emission(f"lamp{lamps}", "flat", tint, None,
                                                        strength=v),
            (px_m(d, x, f), d, px_m(d, -y, f)), px_m(d, rng.uniform(5.0, 7.0), f))
        lamps += 1
    looks = {"sign": ("stripes", (0.8, 0.7, 0.3), (0.1, 0.15, 0.3), 3.0),
             "subject": ("checker", (0.75, 0.7, 0.6), (0.08, 0.07, 0.06), 8.0),
             "near post": ("noise", (0.35, 0.1, 0.06), (0.1, 0.05, 0.03), 6.0),
             "rail": ("noise", (0.1, 0.3, 0.35), (0.05, 0.1, 0.1), 6.0)}
    for name, (d, x, y, w, h, turn) in DOF_LARGE.items():
        tex, a, b, scale = looks[name]
        add(scene, "plane", name, emission(name, tex, a, b, scale=scale),
            (px_m(d, x, f), d, px_m(d, -y, f)), (px_m(d, w, f), 1.0, px_m(d, h, f)),
            rotation=(0.0, math.radians(turn), 0.0))


DOF_SCENES = {"dof_large": scene_dof_large}
"""Depth-of-field scenes: a pinhole frame (dof off) with its Depth pass and Blender's
Defocus node, and Cycles' thin lens as the truth."""

DOF_SAMPLES = 8192
"""Samples per pixel of a depth-of-field truth (6 minutes a seed on 2 shared cores)."""

SCENES = {"spin": scene_spin, "truck": scene_truck, "pan": scene_pan,
          "crossing": scene_crossing, "slow": scene_slow, "truck_rolling": scene_truck,
          **DOF_SCENES}


# -- rendering ---------------------------------------------------------------------------
def exr(scene, multilayer: bool):
    s = scene.render.image_settings
    s.media_type = "MULTI_LAYER_IMAGE" if multilayer else "IMAGE"
    s.file_format = "OPEN_EXR_MULTILAYER" if multilayer else "OPEN_EXR"
    s.color_depth = "16"
    s.exr_codec = "PIZ"
    s.color_mode = "RGBA" if multilayer else "RGB"


def vector_blur_compositor(scene):
    """Render Layers -> Vector Blur (shutter 0.5, 32 samples) -> the composite."""
    tree = bpy.data.node_groups.new("vector blur", "CompositorNodeTree")
    tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
    rl = tree.nodes.new("CompositorNodeRLayers")
    vb = tree.nodes.new("CompositorNodeVecBlur")
    vb.inputs["Samples"].default_value = 32
    vb.inputs["Shutter"].default_value = 0.5
    out = tree.nodes.new("NodeGroupOutput")
    tree.links.new(rl.outputs["Image"], vb.inputs["Image"])
    tree.links.new(rl.outputs["Vector"], vb.inputs["Speed"])
    tree.links.new(rl.outputs["Depth"], vb.inputs["Depth"])
    tree.links.new(vb.outputs["Image"], out.inputs["Image"])
    scene.compositing_node_group = tree
    scene.render.use_compositing = True


def defocus_compositor(scene):
    """Render Layers -> Defocus (the scene camera's focus, clfx's f-number, round bokeh,
    Z buffer from the Depth pass, no blur cap under the frame's largest CoC) -> the
    composite: Blender's own post-process depth of field, the peer row."""
    tree = bpy.data.node_groups.new("defocus", "CompositorNodeTree")
    tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
    rl = tree.nodes.new("CompositorNodeRLayers")
    df = tree.nodes.new("CompositorNodeDefocus")
    df.bokeh = "CIRCLE"
    df.f_stop = DOF_F_NUMBER
    df.blur_max = 128.0
    df.use_zbuffer = True
    out = tree.nodes.new("NodeGroupOutput")
    tree.links.new(rl.outputs["Image"], df.inputs["Image"])
    tree.links.new(rl.outputs["Depth"], df.inputs["Z"])
    tree.links.new(df.outputs["Image"], out.inputs["Image"])
    scene.compositing_node_group = tree
    scene.render.use_compositing = True


def make_dof(name: str, out: str, samples: int, sharp_samples: int) -> None:
    """A depth-of-field scene: the pinhole frame with its Depth pass and the Defocus node,
    then Cycles' thin lens (seeds 1 and 2)."""
    scene, cam = reset()
    DOF_SCENES[name](scene, cam)
    vl = scene.view_layers[0]
    vl.use_pass_z = True
    scene.render.use_motion_blur = False
    dof = cam.data.dof
    dof.use_dof = False
    dof.focus_distance = DOF_FOCUS_M     # the Defocus node's focus (it reads the camera's)
    defocus_compositor(scene)
    exr(scene, multilayer=True)
    render(scene, os.path.join(out, f"{name}.sharp.exr"), samples=sharp_samples)
    scene.render.use_compositing = False
    vl.use_pass_z = False
    dof.use_dof = True
    dof.aperture_fstop = cycles_fstop(DOF_F_NUMBER, DOF_FOCAL_MM, DOF_FOCUS_M)
    dof.aperture_blades = 0          # round, as clfx's camera (blades 0)
    dof.aperture_ratio = 1.0
    exr(scene, multilayer=False)
    for seed in (1, 2):
        render(scene, os.path.join(out, f"{name}.truth{seed}.exr"), samples=samples, seed=seed)


def render(scene, path, *, samples, seed=1):
    scene.cycles.samples = samples
    scene.cycles.seed = seed
    scene.render.filepath = path
    t = time.time()
    bpy.ops.render.render(write_still=True)
    print(f"  {os.path.basename(path)}: {samples} samples, {time.time() - t:.1f} s", flush=True)


def make(name: str, out: str, samples: int, sharp_samples: int) -> None:
    if name in DOF_SCENES:
        return make_dof(name, out, samples, sharp_samples)
    scene, cam = reset()
    SCENES[name](scene, cam)
    scene.frame_set(1)
    vl = scene.view_layers[0]
    vl.use_pass_z = True
    rolling = name.endswith("_rolling")
    if not rolling:
        vl.use_pass_vector = True
        vector_blur_compositor(scene)
    scene.render.use_motion_blur = False
    exr(scene, multilayer=True)
    if not rolling:    # the rolling-shutter scene's sharp frame is its base scene's
        render(scene, os.path.join(out, f"{name}.sharp.exr"), samples=sharp_samples)
    scene.render.use_compositing = False
    vl.use_pass_vector = False
    vl.use_pass_z = False
    scene.render.use_motion_blur = True
    if rolling:
        scene.render.motion_blur_shutter = 0.75
        scene.render.motion_blur_position = "START"
        scene.cycles.rolling_shutter_type = "TOP"
        scene.cycles.rolling_shutter_duration = 0.0
    else:
        scene.render.motion_blur_shutter = 0.5
        scene.render.motion_blur_position = "CENTER"
    exr(scene, multilayer=False)
    for seed in ((1,) if rolling else (1, 2)):   # rolling: no shutter noise, one render
        render(scene, os.path.join(out, f"{name}.truth{seed}.exr"), samples=samples, seed=seed)


def main(argv=None) -> int:
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join(here, "data"))
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--samples", type=int, default=None,
                    help="samples per pixel of a truth (default: 512, 8192 for depth of field)")
    ap.add_argument("--sharp-samples", type=int, default=128)
    args = ap.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    print(f"Blender {bpy.app.version_string}", flush=True)
    for name in args.scenes.split(","):
        print(name, flush=True)
        samples = args.samples or (DOF_SAMPLES if name in DOF_SCENES else 512)
        make(name, args.out, samples, args.sharp_samples)
    return 0


if __name__ == "__main__":
    sys.exit(main())
