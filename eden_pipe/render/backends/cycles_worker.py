"""The Cycles side of ``render.backend=cycles``: a process that holds one Blender scene (``bpy``).

It runs in the interpreter that has ``bpy`` (``render.cycles.python``; bpy 5.0 pins numpy < 2, so
it may live in its own environment) and imports nothing from the package: numpy, bpy and the
standard library only. The parent (:mod:`eden_pipe.render.backends.cycles`) sends pickled
messages over a ``multiprocessing.connection`` socket:

- ``("scene", mesh)``: vertices, faces and per-face albedo, translucency and specular colour;
  the mesh becomes one Blender object with face attributes read by one material;
- ``("world", world)``: the sky as two equirectangular maps (what lights the garden, and what the
  camera sees: the sky plus distant scenery), the sun lamp (direction, irradiance, angular size);
- ``("settings", settings)``: samples, bounces, denoising, device, seed, the sun's glossy lobe;
  answers the device Cycles renders on (``CPU``, or the GPU backend and the GPUs' names);
- ``("view", view)``: intrinsics and camera-to-world pose; renders twice (the camera's rays see
  the diffuse closure and the mirror, lit by the sky and the garden, then the translucent closure
  and the sun's glossy lobe, lit by the sun; every other ray sees diffuse and translucent: Cycles
  files Translucent BSDF light under its diffuse passes) and writes both multilayer EXRs to the
  paths given; the parent reads them;
- ``("close", None)``.

Conventions (docs/design.md, Image formation; docs/realism.md, Cycles): Blender's camera is the
OpenCV camera rotated by diag(1, -1, -1); lens from fx with a horizontal sensor fit; pixel centres
at integer pixel coordinates (Blender's at half-integers: the principal point moves half a pixel);
a Gaussian pixel filter of the narrowest width Blender allows (``backends.cycles.PIXEL_FILTER_WIDTH``),
so a pixel's rays stay within 0.015 px of its centre, the Embree passes' ray.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from multiprocessing.connection import Client

import numpy as np

SENSOR_WIDTH_MM = 36.0
# The glossy lobe (the settings' ``glossy_distribution`` and ``glossy_roughness``: the renderers' Beckmann sun
# lobe, render/backends/cycles.py), kept for a material built after the settings came.
GLOSSY_LOBE: dict = {}


def _bpy():
    import bpy  # imported here: the module is read by tests that lack bpy

    return bpy


def reset() -> None:
    bpy = _bpy()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.render.use_persistent_data = True  # the BVH survives between renders of one scene
    scene.render.film_transparent = False
    scene.render.resolution_percentage = 100
    settings = scene.render.image_settings
    if hasattr(settings, "media_type"):  # Blender 5: multilayer EXR is a media type of OPEN_EXR
        settings.media_type = "MULTI_LAYER_IMAGE"
    settings.file_format = "OPEN_EXR_MULTILAYER"
    scene.render.image_settings.color_depth = "32"
    scene.render.image_settings.exr_codec = "ZIP"
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    scene.cycles.pixel_filter_type = "GAUSSIAN"  # its width comes with the settings (backends.cycles)
    scene.cycles.use_adaptive_sampling = False
    layer = scene.view_layers[0]
    for name in (
        "use_pass_combined",
        "use_pass_diffuse_direct",
        "use_pass_diffuse_indirect",
        "use_pass_diffuse_color",
        "use_pass_glossy_direct",
        "use_pass_glossy_indirect",
        "use_pass_glossy_color",
        "use_pass_environment",
    ):
        setattr(layer, name, True)


def build_mesh(mesh: dict) -> None:
    """One object from the triangle soup, with the face attributes the material reads."""
    bpy = _bpy()
    verts = np.ascontiguousarray(mesh["vertices"], np.float32)
    faces = np.ascontiguousarray(mesh["faces"], np.int32)
    n_faces = len(faces)
    me = bpy.data.meshes.new("garden")
    me.vertices.add(len(verts))
    me.vertices.foreach_set("co", verts.ravel())
    me.loops.add(3 * n_faces)
    me.loops.foreach_set("vertex_index", faces.ravel())
    me.polygons.add(n_faces)
    me.polygons.foreach_set("loop_start", np.arange(0, 3 * n_faces, 3, dtype=np.int32))
    me.polygons.foreach_set("use_smooth", np.zeros(n_faces, bool))  # flat: the face normal, as Embree's
    rgba = np.ones((n_faces, 4), np.float32)
    rgba[:, :3] = mesh["albedo"]
    me.attributes.new("albedo", "FLOAT_COLOR", "FACE").data.foreach_set("color", rgba.ravel())
    for name in ("translucency", "specular"):
        me.attributes.new(name, "FLOAT", "FACE").data.foreach_set("value", np.asarray(mesh[name], np.float32))
    me.update()
    obj = bpy.data.objects.new("garden", me)
    bpy.context.scene.collection.objects.link(obj)
    obj.data.materials.append(garden_material())


def fresnel_ratio(nodes, links):
    """The renderer's Fresnel weight on the light along the mirror (``kernels.glossy_lobe``):
    min(F / 0.04, 2) with Schlick's F = 0.04 + 0.96 (1 - cos v)^5, cos v between the view and the
    shading normal (Cycles turns it toward the viewer), as node math; tests/test_cycles.py holds the two
    together. Returns its output socket."""
    geometry = nodes.new("ShaderNodeNewGeometry")
    cos_v = nodes.new("ShaderNodeVectorMath")
    cos_v.operation = "DOT_PRODUCT"
    links.new(geometry.outputs["Incoming"], cos_v.inputs[0])
    links.new(geometry.outputs["Normal"], cos_v.inputs[1])
    steps = (  # (operation, inputs: None for the previous step's output, clamped to 0-1)
        ("SUBTRACT", (1.0, None), True),
        ("POWER", (None, 5.0), False),
        ("MULTIPLY_ADD", (None, 24.0, 1.0), False),  # 1 + 24 (1 - cos v)^5 = F / 0.04
        ("MINIMUM", (None, 2.0), False),
    )
    socket = cos_v.outputs["Value"]
    for operation, values, clamp in steps:
        node = nodes.new("ShaderNodeMath")
        node.operation, node.use_clamp = operation, clamp
        for k, value in enumerate(values):
            if value is None:
                links.new(socket, node.inputs[k])
            else:
                node.inputs[k].default_value = value
        socket = node.outputs[0]
    return socket


def garden_material():
    """Diffuse(albedo) + Translucent(albedo * translucency) for every ray but the camera's; for camera
    rays the ``part`` value picks Diffuse + the mirror (0) or the translucent closure + the sun's glossy
    lobe (1). The renderer's glossy light is two terms (docs/design.md, Image formation): the sun's lobe
    and the light along the mirror times a Fresnel weight; Cycles has no one closure for both, so each
    render holds one, and :func:`render_view` shows each closure only its own light (ray visibility)."""
    bpy = _bpy()
    mat = bpy.data.materials.new("garden")
    mat.use_nodes = True
    nt = mat.node_tree
    nodes, links = nt.nodes, nt.links
    nodes.clear()

    def attribute(name):
        node = nodes.new("ShaderNodeAttribute")
        node.attribute_type = "GEOMETRY"
        node.attribute_name = name
        return node

    def add(a, b):
        node = nodes.new("ShaderNodeAddShader")
        links.new(a.outputs[0], node.inputs[0])
        links.new(b.outputs[0], node.inputs[1])
        return node

    albedo, trans, spec = attribute("albedo"), attribute("translucency"), attribute("specular")
    diffuse = nodes.new("ShaderNodeBsdfDiffuse")
    links.new(albedo.outputs["Color"], diffuse.inputs["Color"])
    scaled = nodes.new("ShaderNodeVectorMath")
    scaled.operation = "SCALE"
    links.new(albedo.outputs["Vector"], scaled.inputs[0])
    links.new(trans.outputs["Fac"], scaled.inputs["Scale"])
    translucent = nodes.new("ShaderNodeBsdfTranslucent")
    links.new(scaled.outputs["Vector"], translucent.inputs["Color"])
    glossy = nodes.new("ShaderNodeBsdfAnisotropic")  # the Glossy BSDF (one node since Blender 4.0): the sun's lobe
    glossy.name = "glossy"
    set_glossy_lobe(glossy)
    links.new(spec.outputs["Fac"], glossy.inputs["Color"])
    mirror = nodes.new("ShaderNodeBsdfAnisotropic")
    mirror.distribution = "GGX"
    mirror.inputs["Roughness"].default_value = 0.0  # a perfect mirror (Cycles' singular case)
    weighted = nodes.new("ShaderNodeMath")
    weighted.operation = "MULTIPLY"
    links.new(spec.outputs["Fac"], weighted.inputs[0])
    links.new(fresnel_ratio(nodes, links), weighted.inputs[1])
    links.new(weighted.outputs[0], mirror.inputs["Color"])
    # Every other ray: diffuse and translucent only, as the reference path tracer's vertices (glossy
    # reflection is a camera-ray layer in the image formation, docs/design.md), so both carry the same light.
    full = add(diffuse, translucent)
    part = nodes.new("ShaderNodeValue")
    part.name = "part"
    part.outputs[0].default_value = 0.0
    camera_shader = nodes.new("ShaderNodeMixShader")
    links.new(part.outputs[0], camera_shader.inputs["Fac"])
    links.new(add(diffuse, mirror).outputs[0], camera_shader.inputs[1])
    links.new(add(translucent, glossy).outputs[0], camera_shader.inputs[2])
    path = nodes.new("ShaderNodeLightPath")
    pick = nodes.new("ShaderNodeMixShader")
    links.new(path.outputs["Is Camera Ray"], pick.inputs["Fac"])
    links.new(full.outputs[0], pick.inputs[1])
    links.new(camera_shader.outputs[0], pick.inputs[2])
    out = nodes.new("ShaderNodeOutputMaterial")
    links.new(pick.outputs[0], out.inputs["Surface"])
    return mat


def set_glossy_lobe(node=None) -> None:
    """Give the garden material's Glossy BSDF (or ``node``) the settings' lobe, once both exist."""
    if node is None:
        material = _bpy().data.materials.get("garden")
        node = material.node_tree.nodes.get("glossy") if material is not None else None
    if node is not None and GLOSSY_LOBE:
        node.distribution = GLOSSY_LOBE["distribution"]
        node.inputs["Roughness"].default_value = GLOSSY_LOBE["roughness"]


def _image(name: str, rgb: np.ndarray):
    bpy = _bpy()
    h, w = rgb.shape[:2]
    img = bpy.data.images.new(name, w, h, float_buffer=True, alpha=False)
    img.colorspace_settings.name = "Non-Color"  # linear radiance, no transform (set first: it resets the pixels)
    rgba = np.ones((h, w, 4), np.float32)
    rgba[..., :3] = rgb[::-1]  # Blender's rows run bottom-up
    img.pixels.foreach_set(rgba.ravel())
    img.update()
    return img


def build_world(world: dict) -> None:
    """The sky as the world (what lights, and for camera rays what is seen) and the sun lamp."""
    bpy = _bpy()
    scene = bpy.context.scene
    for obj in [o for o in scene.objects if o.type == "LIGHT"]:
        bpy.data.objects.remove(obj, do_unlink=True)
    w = bpy.data.worlds.new("sky")
    scene.world = w
    w.use_nodes = True
    nodes, links = w.node_tree.nodes, w.node_tree.links
    nodes.clear()
    lit, seen = nodes.new("ShaderNodeTexEnvironment"), nodes.new("ShaderNodeTexEnvironment")
    lit.image, seen.image = _image("sky_light", world["light_map"]), _image("sky_seen", world["camera_map"])
    for node in (lit, seen):
        node.interpolation = "Linear"
    path = nodes.new("ShaderNodeLightPath")
    mix = nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA"
    links.new(path.outputs["Is Camera Ray"], mix.inputs["Factor"])
    links.new(lit.outputs["Color"], _socket(mix.inputs, "A_Color"))  # the colour sockets, not the float ones
    links.new(seen.outputs["Color"], _socket(mix.inputs, "B_Color"))
    background = nodes.new("ShaderNodeBackground")
    background.inputs["Strength"].default_value = 1.0
    links.new(_socket(mix.outputs, "Result_Color"), background.inputs["Color"])
    out = nodes.new("ShaderNodeOutputWorld")
    links.new(background.outputs[0], out.inputs["Surface"])
    irradiance = np.asarray(world["sun_irradiance"], np.float64)
    if float(irradiance.max()) > 0:
        lamp = bpy.data.lights.new("sun", "SUN")
        lamp.energy = float(irradiance.max())  # W/m^2: the irradiance on a surface facing the sun
        lamp.color = tuple(float(c) for c in irradiance / irradiance.max())
        lamp.angle = float(2.0 * world["sun_angular_radius"])
        obj = bpy.data.objects.new("sun", lamp)
        scene.collection.objects.link(obj)
        obj.rotation_mode = "QUATERNION"
        obj.rotation_quaternion = _quaternion_pointing(-np.asarray(world["sun_direction"], np.float64))


def _socket(sockets, identifier: str):
    return next(s for s in sockets if s.identifier == identifier)


def _quaternion_pointing(direction: np.ndarray):
    """The rotation taking the lamp's -Z (where a sun shines) onto ``direction``."""
    from mathutils import Vector

    return Vector((0.0, 0.0, -1.0)).rotation_difference(Vector(tuple(float(c) for c in direction)))


def apply_settings(settings: dict) -> dict:
    bpy = _bpy()
    scene = bpy.context.scene
    c = scene.cycles
    c.samples = int(settings["samples"])
    c.seed = int(settings["seed"])
    c.use_denoising = False  # it would clean only the combined image: the layers must compose into rgb exactly
    c.max_bounces = int(settings["max_bounces"])
    c.diffuse_bounces = int(settings["diffuse_bounces"])
    c.glossy_bounces = int(settings["glossy_bounces"])
    c.transmission_bounces = int(settings["transmission_bounces"])
    c.transparent_max_bounces = 8
    c.sample_clamp_direct = float(settings["clamp_direct"])
    c.sample_clamp_indirect = float(settings["clamp_indirect"])
    c.caustics_reflective = c.caustics_refractive = False
    c.filter_width = float(settings["filter_width"])
    scene.render.threads_mode = "FIXED" if int(settings["threads"]) > 0 else "AUTO"
    if int(settings["threads"]) > 0:
        scene.render.threads = int(settings["threads"])
    c.device = choose_device(str(settings["device"]))
    GLOSSY_LOBE.update(distribution=str(settings["glossy_distribution"]), roughness=float(settings["glossy_roughness"]))
    set_glossy_lobe()
    return device_facts()


def device_facts() -> dict:
    """What Cycles renders on: ``device`` ``CPU`` or the GPU backend (``OPTIX``, ``CUDA``, ...), and
    ``names``, the GPUs in use."""
    bpy = _bpy()
    if bpy.context.scene.cycles.device != "GPU":
        return {"device": "CPU", "names": []}
    prefs = bpy.context.preferences.addons["cycles"].preferences
    return {"device": prefs.compute_device_type, "names": [d.name for d in prefs.devices if d.use]}


def choose_device(device: str) -> str:
    """``cpu``, or ``auto``: the first GPU backend Blender finds (OptiX, CUDA, HIP, oneAPI, Metal), else CPU."""
    if device == "cpu":
        return "CPU"
    bpy = _bpy()
    prefs = bpy.context.preferences.addons["cycles"].preferences
    for kind in ("OPTIX", "CUDA", "HIP", "ONEAPI", "METAL"):
        try:
            prefs.compute_device_type = kind
        except TypeError:  # not built into this Blender
            continue
        prefs.refresh_devices()
        gpus = [d for d in prefs.devices if d.type == kind]
        if gpus:
            for d in prefs.devices:
                d.use = d.type == kind
            return "GPU"
    return "CPU"


def camera(view: dict) -> None:
    """The OpenCV pinhole (K, camera-to-world) as Blender's camera (module doc: conventions)."""
    bpy = _bpy()
    from mathutils import Matrix

    scene = bpy.context.scene
    w, h = int(view["width"]), int(view["height"])
    fx, fy, cx, cy = (float(view[k]) for k in ("fx", "fy", "cx", "cy"))
    scene.render.resolution_x, scene.render.resolution_y = w, h
    scene.render.pixel_aspect_x, scene.render.pixel_aspect_y = 1.0, fx / fy  # fy != fx: non-square pixels
    cam = scene.camera
    if cam is None:
        cam = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
        scene.collection.objects.link(cam)
        scene.camera = cam
    data = cam.data
    data.sensor_fit = "HORIZONTAL"
    data.sensor_width = SENSOR_WIDTH_MM
    data.lens = fx * SENSOR_WIDTH_MM / w
    data.clip_start, data.clip_end = 1e-3, 1e5
    size = max(w, h * fy / fx)
    data.shift_x = (0.5 * w - (cx + 0.5)) / size
    data.shift_y = ((cy + 0.5) - 0.5 * h) / size * (fx / fy)
    pose = np.asarray(view["pose"], np.float64).copy()
    pose[:3, :3] = pose[:3, :3] @ np.diag([1.0, -1.0, -1.0])
    cam.matrix_world = Matrix([list(map(float, row)) for row in pose])


def render_view(view: dict) -> dict:
    """Both renders of one view (module doc), each written to its path; seconds each, and the device
    (``CPU``, or the GPU backend: ``OPTIX``, ``CUDA``, ...)."""
    bpy = _bpy()
    scene = bpy.context.scene
    camera(view)
    part = bpy.data.materials["garden"].node_tree.nodes["part"] if "garden" in bpy.data.materials else None
    seconds = []
    lamps = [o for o in scene.objects if o.type == "LIGHT"]
    for i, path in enumerate(view["paths"]):
        if part is not None:
            part.outputs[0].default_value = float(i)
        # The mirror (first render) sees the sky and the garden, not the sun; the sun's lobe (second)
        # the sun alone: the renderer's two glossy terms (garden_material).
        for lamp in lamps:
            lamp.visible_glossy = i == 1
        if scene.world is not None:
            scene.world.cycles_visibility.glossy = i == 0
        scene.render.filepath = path
        t0 = time.perf_counter()
        bpy.ops.render.render(write_still=True)
        seconds.append(time.perf_counter() - t0)
    return {"seconds": seconds, "device": device_facts()["device"]}


def arrays(value):
    """The parent's version-neutral arrays (``cycles.plain``) back as numpy arrays."""
    if isinstance(value, tuple) and len(value) == 4 and value[0] == "ndarray":
        return np.frombuffer(value[3], dtype=np.dtype(value[1])).reshape(value[2])
    if isinstance(value, dict):
        return {k: arrays(v) for k, v in value.items()}
    return value


def exit_with_parent(interval_s: float = 1.0) -> None:
    """End this process when its parent goes. A parent killed mid-render never closes the loop below
    (the socket is read only between renders), and a GPU's first render can compile kernels for
    minutes (docs/realism.md, Cycles): a thread watches, which runs since Cycles releases the GIL
    while it renders."""
    parent = os.getppid()

    def watch() -> None:
        while True:
            time.sleep(interval_s)
            if os.getppid() != parent:
                os._exit(1)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


def serve(address: str, authkey: bytes) -> None:
    exit_with_parent()
    reset()
    conn = Client(address, authkey=authkey)
    handlers = {
        "scene": build_mesh,
        "world": build_world,
        "settings": apply_settings,
        "view": render_view,
    }
    bpy = _bpy()
    conn.send(("ready", {"blender": bpy.app.version_string, "numpy": np.__version__}))
    while True:
        kind, payload = conn.recv()
        if kind == "close":
            conn.send(("ok", None))
            break
        try:
            conn.send(("ok", handlers[kind](arrays(payload))))
        except Exception as exc:  # noqa: BLE001  (reported to the parent, which raises it)
            conn.send(("error", f"{type(exc).__name__}: {exc}"))
    conn.close()


if __name__ == "__main__":
    serve(sys.argv[1], bytes.fromhex(os.environ["EDEN_CYCLES_AUTHKEY"]))
