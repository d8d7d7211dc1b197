"""Pre-flight checks (docs/reliability.md): unknown keys, destination folders, the disk-space estimate.
Fast: no stage runs here (the fault tests run real jobs)."""

from __future__ import annotations

import pytest
from conftest import TINY

from eden_pipe import modalities
from eden_pipe.config import ConfigError, check_known_keys, schema_keys, to_config
from eden_pipe.config.domains import Where, WritableFolder
from eden_pipe.preflight import row_bytes, space_needed


def test_allowed_keys_come_from_the_dataclasses(cfg_factory):
    keys = schema_keys()
    assert {
        "garden.trees.count",
        "camera.trajectory.frames",
        "camera.trajectory.share_across_lightings",
        "lighting.turbidity",
        "paths.check_free_space",
        "split.overrides",
        "split.test_subsample.seed",
    } <= set(keys)
    assert not [k for k in keys if k.startswith("split.overrides.")]  # free-form: any garden id
    check_known_keys(cfg_factory(["++split.overrides={small-s0: test, other-s1: val}"]))  # accepted


@pytest.mark.parametrize(
    "node,words",
    [
        (
            {"garden": {"tress": {"count": [5, 6]}}},
            ["garden.tress", "did you mean garden.trees?", "allowed under garden:"],
        ),
        ({"render": {"max_frame": 3}}, ["render.max_frame=3", "did you mean render.max_frames?"]),
        ({"trees": {"count": [1, 2]}}, ["did you mean garden.trees?", "allowed at the top level"]),
        ({"zzz": 1}, ["zzz=1 is not a known key; allowed at the top level: camera, force"]),
    ],
)
def test_unknown_keys_are_rejected_with_a_suggestion(node, words):
    with pytest.raises(ConfigError) as err:
        check_known_keys(node)
    for word in words:
        assert word in str(err.value)
    assert "\n" not in str(err.value)


def test_to_config_rejects_unknown_keys_but_ignores_hydras_node(cfg_factory):
    from omegaconf import OmegaConf

    cfg = cfg_factory(["garden=small"])
    plain = OmegaConf.to_container(cfg)
    to_config(OmegaConf.create({**plain, "hydra": {"job": {"name": "x"}}}))
    plain["garden"]["tress"] = 1
    with pytest.raises(ConfigError, match=r"garden\.tress"):
        to_config(OmegaConf.create(plain))


def test_writable_check_never_creates_the_folder(tmp_path):
    def check_writable(key, value):  # the domain of paths.stages and paths.dataset
        WritableFolder().check(value, Where(key, str, None))

    target = tmp_path / "a" / "b" / "dataset"
    check_writable("paths.dataset", str(target))
    assert list(tmp_path.iterdir()) == []
    (tmp_path / "file").write_text("x")
    with pytest.raises(ConfigError, match="not a folder"):
        check_writable("paths.dataset", str(tmp_path / "file" / "dataset"))
    with pytest.raises(ConfigError, match=r"paths.stages='/proc/x'.*a folder this user can write"):
        check_writable("paths.stages", "/proc/x")


def test_row_bytes_follow_the_modality_table(cfg_factory):
    cfg = to_config(cfg_factory(TINY))
    pixels = cfg.camera.width * cfg.camera.height
    options = modalities.WriteOptions.from_config(cfg.render)
    middle = modalities.columns_for(cfg.render.modalities, True, True)
    assert row_bytes(cfg) == int(sum(c.file_format(options).pixel_bytes for c in middle) * pixels)
    assert row_bytes(cfg, has_prev=False) < row_bytes(cfg)  # no backward flow on the first frame
    exact = to_config(cfg_factory([*TINY, "render.storage=exact"]))
    assert row_bytes(exact) > row_bytes(cfg)  # float32 .npy and .flo against half EXR and PNG


def test_space_needed_counts_every_frame_and_camera_of_an_empty_cache(cfg_factory):
    cfg = to_config(cfg_factory(TINY))
    (need,) = space_needed(cfg)
    n = cfg.camera.trajectory.frame_range()[0]  # TINY: frames=[4,4]
    frames = sum(row_bytes(cfg, f + 1 < n, f > 0) for f in range(n)) * cfg.camera.pairs
    assert need.need > frames and f"{n} frames x {cfg.camera.pairs} camera pairs" in need.detail
    assert not (need.path / "stages").exists()  # nothing written by the estimate
