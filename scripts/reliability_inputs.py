"""The bad inputs of ``scripts/reliability_table.py``: every row a user could type or write that must
stop the job before any work (exit 2, one line, nothing written).

Each :class:`BadInput` is a kind (override, unknown key, schema, path, garden file, preset), a
label for the table, the command line's arguments, the words its message must contain, and what it
writes first (a user's garden file, a file where a folder goes, an edited copy of a shipped preset).
``tests/test_bad_inputs.py`` runs a sample of them through the real command line.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from reliability_table import Inputs


@dataclass
class BadInput:
    kind: str  # override, unknown key, schema, path, garden file, preset
    label: str  # what is wrong, for the table
    args: list[str]
    words: list[str] = field(default_factory=list)  # the message must contain each
    setup: Callable[[Inputs], list[str]] | None = None  # writes input files, returns extra args
    preset: tuple[str, str, Callable[[dict], None]] | None = None  # (kind, shipped preset, edit)


def _garden_file(name: str, text: str) -> Callable[[Inputs], list[str]]:
    def setup(inputs: Inputs) -> list[str]:
        folder = inputs.folder / "gardens" / "garden"
        folder.mkdir(parents=True, exist_ok=True)
        (folder / f"{name}.yaml").write_text(text)
        return [f"--config-dir={inputs.folder / 'gardens'}", f"garden={name}"]

    return setup


def _a_file(inputs: Inputs) -> list[str]:
    path = inputs.folder / "a_file"
    path.write_text("not a folder\n")
    return [f"paths.dataset={path}"]


def _under_a_file(inputs: Inputs) -> list[str]:
    path = inputs.folder / "a_file"
    path.write_text("not a folder\n")
    return [f"paths.stages={path}/stages"]


def _set(key: str, value) -> Callable[[dict], None]:
    def edit(preset: dict) -> None:
        node = preset
        *parents, leaf = key.split(".")
        for part in parents:
            node = node[part]
        node[leaf] = value

    return edit


def _drop(key: str) -> Callable[[dict], None]:
    return lambda preset: preset.pop(key)


GARDEN_HEAD = "defaults:\n  - small\n  - _self_\nname: mine\n"
POOL_ARG = {
    "trees": "garden.trees.types",
    "bushes": "garden.bushes.types",
    "flowers": "garden.flowers.types",
    "assets": "garden.obstacles.types",
    "grass": "garden.lawn.species",
}

BAD_INPUTS: list[BadInput] = [
    # ---- values out of range, on the command line (config.validate)
    BadInput("override", "count lo > hi", ["garden.trees.count=[17,5]"], ["garden.trees.count", "17", "lo <= hi"]),
    BadInput("override", "negative count", ["garden.obstacles.count=[-1,3]"], ["garden.obstacles.count", "-1", ">= 0"]),
    BadInput("override", "unknown species", ["garden.trees.types=[quaking_aspen,baobab]"], ["baobab", "quaking_aspen"]),
    BadInput("override", "unknown depth format", ["render.depth_format=exr"], ["render.depth_format", "png16"]),
    BadInput(
        "override", "sun elevation lo > hi", ["lighting.sun_elevation_deg=[60,30]"], ["lighting.sun_elevation_deg"]
    ),
    BadInput(
        "override",
        "sun below the horizon for clear",
        ["lighting=clear", "lighting.sun_elevation_deg=[-5,10]"],
        ["lighting.sun_elevation_deg", "-5"],
    ),
    BadInput(
        "override", "turbidity beyond the sky model", ["lighting.turbidity=[12,15]"], ["lighting.turbidity", "12"]
    ),
    BadInput(
        "override", "one-frame trajectory", ["camera.trajectory.frames=[1,1]"], ["camera.trajectory.frames", ">= 2"]
    ),
    BadInput("override", "unknown stage in force", ["force=[rendr]"], ["force", "rendr", "render"]),
    BadInput("override", "negative seed", ["garden.seed=-3"], ["garden.seed", "-3"]),
    BadInput("override", "zero garden size", ["garden.size_m=0"], ["garden.size_m", "> 0"]),
    BadInput("override", "zero image width", ["camera.width=0"], ["camera.width", "> 0"]),
    BadInput("override", "pitch beyond 89 deg", ["camera.pitch_deg=95"], ["camera.pitch_deg", "95"]),
    BadInput("override", "unknown modality", ["render.modalities=[rgb,thermal]"], ["render.modalities", "thermal"]),
    BadInput("override", "no modality", ["render.modalities=[]"], ["render.modalities", "non-empty"]),
    BadInput("override", "unknown backend", ["render.backend=blender"], ["render.backend", "blender"]),
    BadInput("override", "unknown storage mode", ["render.storage=lossy"], ["render.storage", "compact"]),
    BadInput("override", "PNG compression 12", ["render.png_compression=12"], ["render.png_compression", "0..9"]),
    BadInput("override", "zero max frames", ["render.max_frames=0"], ["render.max_frames", ">= 1"]),
    BadInput("override", "zero samples per pixel", ["render.rgb_spp=0"], ["render.rgb_spp", "> 0"]),
    BadInput("override", "negative thread count", ["render.threads=-1"], ["render.threads", ">= 0"]),
    BadInput("override", "split fractions sum to 1.1", ["split.train=0.9"], ["split", "summing to 1"]),
    BadInput("override", "unknown split preset", ["split.preset=random"], ["split.preset", "hash"]),
    BadInput("override", "unknown split in overrides", ["++split.overrides={small-s0:holdout}"], ["holdout", "train"]),
    BadInput("override", "subsample fraction 1.5", ["split.test_subsample.fraction=1.5"], ["fraction", "1.5"]),
    BadInput(
        "override", "stripes probability 2", ["garden.lawn.stripes_probability=2"], ["stripes_probability", "[0, 1]"]
    ),
    BadInput("override", "unknown terrain type", ["garden.terrain.patch_types=[grass,lava]"], ["patch_types", "lava"]),
    BadInput(
        "override", "patch weights of the wrong length", ["garden.terrain.patch_weights=[1,1]"], ["patch_weights"]
    ),
    BadInput("override", "unknown fence style", ["garden.fences.styles=[brick]"], ["garden.fences.styles", "brick"]),
    BadInput("override", "turn angle 270 deg", ["camera.trajectory.turn_deg=[0,270]"], ["turn_deg", "180"]),
    BadInput(
        "override",
        "negative probability",
        ["camera.trajectory.abrupt_turn_probability=-0.1"],
        ["abrupt_turn_probability", "-0.1"],
    ),
    BadInput(
        "override", "unknown lawn species", ["garden.lawn.species=[astroturf]"], ["garden.lawn.species", "astroturf"]
    ),
    BadInput(
        "override", "cloud cover above 1", ["lighting=cloudy", "lighting.cloud_cover=[0.5,2]"], ["lighting.cloud_cover"]
    ),
    # ---- accepted before every key's domain was declared in the schema (tests/test_config_schema.py tries
    # them all): a traceback mid-job, or a job that could not end well
    BadInput(
        "override", "zero lawn density", ["garden.lawn.triangles_per_m2=0"], ["garden.lawn.triangles_per_m2", "> 0"]
    ),
    BadInput("override", "infinite garden size", ["garden.size_m=inf"], ["garden.size_m", "> 0"]),
    BadInput("override", "empty garden name", ["garden.name=''"], ["garden.name", "non-empty"]),
    BadInput("override", "number for the lawn's species", ["garden.lawn.species=5"], ["garden.lawn.species", "'all'"]),
    BadInput("schema", "string for a mapping", ["split.overrides=foo"], ["split.overrides", "a mapping"]),
    # ---- keys the schema does not know (config.check_known_keys): a did-you-mean where one is close
    BadInput("unknown key", "unknown top-level key", ["+unknown_key=1"], ["unknown_key", "not a known key"]),
    BadInput(
        "unknown key",
        "typo in a section (tress)",
        ["+garden.tress.count=[5,6]"],
        ["garden.tress", "did you mean garden.trees"],
    ),
    BadInput("unknown key", "typo in a leaf (max_frame)", ["+render.max_frame=3"], ["did you mean render.max_frames"]),
    BadInput(
        "unknown key", "typo in lighting (turbidty)", ["+lighting.turbidty=[2,3]"], ["did you mean lighting.turbidity"]
    ),
    BadInput(
        "unknown key",
        "typo deep down (frame)",
        ["+camera.trajectory.frame=[10,10]"],
        ["did you mean camera.trajectory.frames"],
    ),
    BadInput("unknown key", "section left out (trees.count)", ["+trees.count=[1,2]"], ["did you mean garden.trees"]),
    BadInput("unknown key", "override of an unknown key", ["garden.colour=red"], ["garden.colour", "not a known key"]),
    # ---- what Hydra rejects while composing (cli_errors.hydra_error_line)
    BadInput("schema", "string for an integer", ["camera.width=wide"], ["camera.width", "an integer"]),
    BadInput("schema", "number for a list", ["garden.trees.count=5"], ["garden.trees.count", "a list of integers"]),
    BadInput("schema", "word for a boolean", ["progress=maybe"], ["progress", "true or false"]),
    BadInput(
        "schema", "string for null-or-integer", ["render.max_frames=abc"], ["render.max_frames", "null or an integer"]
    ),
    BadInput("schema", "number for a section", ["garden.lawn=3"], ["garden.lawn", "a section"]),
    BadInput("schema", "string for a section", ["garden.trees=foo"], ["garden.trees", "a section"]),
    BadInput("schema", "unknown lighting scenario file", ["lighting=midnight"], ["lighting", "midnight", "clear"]),
    BadInput("schema", "unknown garden file", ["garden=nosuch"], ["garden", "nosuch", "small"]),
    BadInput("schema", "unknown camera file", ["camera=fisheye"], ["camera", "fisheye", "ring5_stereo"]),
    BadInput("schema", "unparsable override", ["garden.seed=["], ["cannot parse"]),
    BadInput("schema", "deleting a required key", ["~garden.seed"], ["garden.seed", "cannot be removed"]),
    BadInput("schema", "appending an existing key", ["+garden.seed=3"], ["garden.seed"]),
    # ---- destination folders and disk space (preflight)
    BadInput("path", "dataset under /proc", ["paths.dataset=/proc/forbidden"], ["paths.dataset", "/proc"]),
    BadInput("path", "stage cache under /proc", ["paths.stages=/proc/forbidden"], ["paths.stages", "/proc"]),
    BadInput(
        "path", "dataset on a read-only filesystem (/sys)", ["paths.dataset=/sys/eden"], ["paths.dataset", "/sys"]
    ),
    BadInput("path", "dataset path is a file", [], ["paths.dataset", "not a folder"], setup=_a_file),
    BadInput("path", "stage cache under a file", [], ["paths.stages", "not a folder"], setup=_under_a_file),
    BadInput(
        "path",
        "job larger than the free disk",
        ["camera.width=100000", "camera.height=100000"],
        ["not enough free space", "free at", "paths.check_free_space=false"],
    ),
    # ---- a user's own garden file (--config-dir)
    BadInput(
        "garden file",
        "unknown key in the file",
        [],
        ["mine.yaml", "garden.tress", "did you mean garden.trees"],
        setup=_garden_file("mine", GARDEN_HEAD + "tress:\n  count: [5, 6]\n"),
    ),
    BadInput(
        "garden file",
        "wrong type in the file",
        [],
        ["mine.yaml", "garden.seed", "an integer"],
        setup=_garden_file("mine", GARDEN_HEAD + "seed: abc\n"),
    ),
    BadInput(
        "garden file",
        "out-of-range value in the file",
        [],
        ["mine.yaml", "garden.trees.count", "lo <= hi"],
        setup=_garden_file("mine", GARDEN_HEAD + "trees:\n  count: [5, 1]\n"),
    ),
    BadInput(
        "garden file",
        "unknown species in the file",
        [],
        ["mine.yaml", "garden.bushes.types", "baobab"],
        setup=_garden_file("mine", GARDEN_HEAD + "bushes:\n  types: [baobab]\n"),
    ),
    BadInput(
        "garden file",
        "not YAML",
        [],
        ["mine.yaml", "invalid YAML"],
        setup=_garden_file("mine", GARDEN_HEAD + "trees: [unclosed\n"),
    ),
    # ---- a user's own species or asset preset (conf/species/<kind>/, models.presets and the loaders)
    BadInput(
        "preset",
        "tree: unknown key (Levles)",
        [],
        ["user_preset.yaml", "Levles"],
        preset=("trees", "palm", lambda p: p.update(Levles=p.pop("Levels"))),
    ),
    BadInput(
        "preset",
        "tree: word for a number (Levels: two)",
        [],
        ["user_preset.yaml", "Levels", "two"],
        preset=("trees", "palm", _set("Levels", "two")),
    ),
    BadInput(
        "preset",
        "tree: NaN",
        [],
        ["user_preset.yaml", "Scale", "finite"],
        preset=("trees", "palm", _set("Scale", float("nan"))),
    ),
    BadInput(
        "preset",
        "tree: empty value",
        [],
        ["user_preset.yaml", "Ratio", "empty"],
        preset=("trees", "palm", _set("Ratio", None)),
    ),
    BadInput(
        "preset",
        "tree: 3 levels where 4 go",
        [],
        ["user_preset.yaml", "nLength", "4 numbers"],
        preset=("trees", "palm", _set("nLength", [1.0, 0.4, 0.0])),
    ),
    BadInput(
        "preset",
        "bush: string for a range",
        [],
        ["user_preset.yaml", "skeleton.length"],
        preset=("bushes", "hedge_box", _set("skeleton.length", "long")),
    ),
    BadInput(
        "preset",
        "bush: unknown key in a section",
        [],
        ["user_preset.yaml", "leafs"],
        preset=("bushes", "hedge_box", lambda p: p.update(leafs=p.pop("leaves"))),
    ),
    BadInput(
        "preset",
        "flower: unknown kind",
        [],
        ["user_preset.yaml", "orchid"],
        preset=("flowers", "daisy", _set("kind", "orchid")),
    ),
    BadInput(
        "preset",
        "flower: empty choice",
        [],
        ["user_preset.yaml", "rays", "choice"],
        preset=("flowers", "daisy", _set("rays", {"choice": []})),
    ),
    BadInput(
        "preset",
        "asset: unknown family",
        [],
        ["user_preset.yaml", "statue"],
        preset=("assets", "rock_round", _set("family", "statue")),
    ),
    BadInput(
        "preset",
        "asset: number for a list of colours",
        [],
        ["user_preset.yaml", "colors"],
        preset=("assets", "rock_round", _set("colors", 0.3)),
    ),
    BadInput(
        "preset",
        "grass: string for a count",
        [],
        ["user_preset.yaml", "density_per_m2", "lots"],
        preset=("grass", "bermuda", _set("density_per_m2", "lots")),
    ),
    BadInput(
        "preset",
        "grass: unknown kind",
        [],
        ["user_preset.yaml", "moss"],
        preset=("grass", "bermuda", _set("kind", "moss")),
    ),
]
