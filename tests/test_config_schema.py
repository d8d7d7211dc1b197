"""One source per setting: the schema's defaults are the shipped ``conf/`` values, and every key
of the schema, enumerated from the dataclasses, rejects a value of the wrong type and values out
of its domain with the one-line config error and exit 2 before any work.

The bulk runs in-process through the command line's own path (Hydra composition, then the Hydra
callback that runs the pre-flight check before Hydra makes a folder); a few cases run as real
``python -m eden_pipe`` processes.
"""

from __future__ import annotations

import copy
import functools
import math
import os
import re
import subprocess
import sys
import typing
from dataclasses import dataclass
from pathlib import Path

import pytest
from omegaconf import OmegaConf

from eden_pipe.callbacks import EdenCallback
from eden_pipe.cli_errors import hydra_error_line
from eden_pipe.config import CONF_DIR, EdenConfig, LightingConfig, make_cfg, schema_items, to_plain
from eden_pipe.config.domains import Where
from eden_pipe.lighting import SCENARIOS

REPO = Path(__file__).resolve().parents[1]
MESSAGE = re.compile(r"^eden-pipe: invalid config: ([\w.\-~]+?)(=| is not| cannot)")


def same(a, b, where: str = "") -> list[str]:
    """Where ``a`` and ``b`` differ, in value or in type (35 and 35.0 differ: a YAML int stays one)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return [
            d
            for k in dict.fromkeys([*a, *b])
            for d in (same(a[k], b[k], f"{where}.{k}".lstrip(".")) if k in a and k in b else [f"{where}.{k}: missing"])
        ]
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        return [d for i, (x, y) in enumerate(zip(a, b, strict=True)) for d in same(x, y, f"{where}[{i}]")]
    return [] if type(a) is type(b) and a == b else [f"{where}: conf/ {a!r}, schema {b!r}"]


# ------------------------------------------------------------------ one source of defaults
def test_schema_defaults_are_the_shipped_config():
    shipped = OmegaConf.to_container(make_cfg(None), resolve=True)
    assert same(shipped, to_plain(EdenConfig())) == []


@pytest.mark.parametrize("name", SCENARIOS)
def test_each_lighting_file_is_its_scenarios_defaults(name):
    shipped = OmegaConf.to_container(make_cfg(None, [f"lighting={name}"]).lighting, resolve=True)
    assert same(shipped, to_plain(LightingConfig.for_scenario(name))) == []


# ------------------------------------------------------------------ every key, bad values
def wrong_type(kind) -> str:
    """An override value of another type than the key's (a string where a mapping goes, ...)."""
    inner = [a for a in typing.get_args(kind) if a is not type(None)]
    if typing.get_origin(kind) is typing.Union:
        kind = inner[0]
    if kind is typing.Any:
        return "{a:1}"  # a mapping where a number, a list or a word goes
    if kind is bool:
        return "maybe"
    if kind is str:
        return "[1,2]"
    return "abc"  # for numbers, lists, mappings and sections


def hydra_value(value) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, str):
        return f"'{value}'"
    if isinstance(value, float) and math.isinf(value):
        return "inf" if value > 0 else "-inf"
    if isinstance(value, list):
        return "[" + ",".join(hydra_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ",".join(f"{k}:{hydra_value(v)}" for k, v in value.items()) + "}"
    return repr(value)


@dataclass(frozen=True)
class Case:
    key: str  # the key the message must name (or a key under it)
    what: str  # "wrong type" or "outside"
    overrides: tuple[str, ...]

    @property
    def id(self) -> str:
        return f"{self.what}:{' '.join(self.overrides)}"


def node_at(root, key: str):
    for part in key.split("."):
        root = getattr(root, part)
    return root


def bad_input_cases() -> tuple[list[str], list[Case]]:
    """(every key of the schema, the cases tried): one of the wrong type per key, and each value its
    domain (or its section's rule) gives as outside it."""
    default = EdenConfig()
    keys, cases = [], []
    for item in schema_items():
        keys.append(item.key)
        cases.append(Case(item.key, "wrong type", (f"{item.key}={wrong_type(item.kind)}",)))
        if item.domain is not None:
            section_key = item.key.rpartition(".")[0]
            where = Where(item.key, item.kind, node_at(default, section_key) if section_key else default)
            cases += [
                Case(item.key, "outside", (f"{'++' if isinstance(v, dict) else ''}{item.key}={hydra_value(v)}",))
                for v in item.domain.outside(where)
            ]  # ++: a mapping's keys are new keys
        for rule in item.checks:  # a rule over the section's keys: the message names the section or the key
            for values in rule.outside(node_at(default, item.key)):
                overrides = tuple(f"{item.key}.{k}={hydra_value(v)}" for k, v in values.items())
                cases.append(Case(item.key, "rule", overrides))
    return keys, cases


KEYS, CASES = bad_input_cases()


def test_every_key_is_tried_and_every_value_key_has_a_domain():
    items = list(schema_items())
    assert [item.key for item in items] == KEYS and len(set(KEYS)) == len(KEYS)
    covered = {case.key for case in CASES if case.what == "outside"}
    covered |= {o.partition("=")[0] for case in CASES if case.what == "rule" for o in case.overrides}
    free = [
        item.key
        for item in items
        if item.section is None and item.kind is not bool and item.key not in covered and item.domain is None
    ]
    assert free == [], "keys without a domain (declare one with config.domains.setting)"
    # Reported in the test log: how much of the schema the bad-input cases cover.
    print(
        f"\n{len(KEYS)} keys ({sum(i.section is None for i in items)} values, "
        f"{sum(i.section is not None for i in items)} sections), {len(CASES)} bad-input cases "
        f"({sum(c.what == 'wrong type' for c in CASES)} of the wrong type, "
        f"{sum(c.what != 'wrong type' for c in CASES)} outside a key's domain or its section's rules)"
    )
    assert len(KEYS) >= 140 and len(CASES) >= 2 * len(KEYS)


GROUPS = {p.name for p in CONF_DIR.iterdir() if p.is_dir()}  # garden=..., lighting=...: a file of the group


@functools.lru_cache(maxsize=1)
def composed_default():
    return make_cfg(None)


def compose(root: Path, overrides: list[str]):
    """``make_cfg(root, overrides)``, fast: Hydra composes the defaults once, then each case's value
    overrides go through Hydra's own override step (``ConfigLoaderImpl._apply_overrides_to_config``,
    what ``compose`` runs last); an override that picks a group's file composes afresh."""
    overrides = [f"paths.stages={root}/stages", f"paths.dataset={root}/dataset", *overrides]
    if any(o.partition("=")[0].lstrip("+~") in GROUPS for o in overrides):
        return make_cfg(None, overrides)
    from hydra._internal.config_loader_impl import ConfigLoaderImpl
    from hydra.core.override_parser.overrides_parser import OverridesParser

    cfg = copy.deepcopy(composed_default())
    ConfigLoaderImpl._apply_overrides_to_config(OverridesParser.create().parse_overrides(overrides), cfg)
    return cfg


def cli_line(root: Path, overrides: list[str], capsys) -> str:
    """What the command line prints for ``overrides`` before any work: Hydra's composition error as
    ``__main__.cli`` turns it into one line, else the Hydra callback's pre-flight check (exit 2)."""
    try:
        cfg = compose(root, overrides)
    except Exception as ex:  # noqa: BLE001 - as cli() catches around hydra.main: any composition error
        line = hydra_error_line(ex, overrides)
        assert line is not None, f"not a one-line error: {ex!r}"
        return f"eden-pipe: {line}"
    capsys.readouterr()
    with pytest.raises(SystemExit) as stopped:
        EdenCallback().on_run_start(cfg)
    assert stopped.value.code == 2
    return capsys.readouterr().err.strip()


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_a_bad_value_of_any_key_stops_before_any_work(case, tmp_path, capsys):
    line = cli_line(tmp_path / "job", list(case.overrides), capsys)
    named = MESSAGE.match(line)
    assert named and "\n" not in line and "allowed: any value" not in line, line
    if case.what == "rule":
        assert named.group(1) in [case.key] + [o.partition("=")[0] for o in case.overrides], (case.key, line)
    else:
        assert named.group(1) == case.key or named.group(1).startswith(case.key + "."), (case.key, line)
    assert list(tmp_path.iterdir()) == [], "nothing may be written"


# A few of the cases above through the real command line.
SUBPROCESS = [
    "garden.trees=abc",
    "split.overrides=abc",
    "garden.lawn.species={a:1}",
    "garden.lawn.triangles_per_m2=0",
    "garden.size_m=inf",
    "render.sky_visibility.directions=0",
]


@pytest.mark.parametrize("override", SUBPROCESS)
def test_the_command_line_gives_the_same_line_and_exit_2(override, tmp_path, capsys):
    case = next(c for c in CASES if c.overrides == (override,))
    folder = tmp_path / "job"
    folder.mkdir()
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    env.pop("HYDRA_FULL_ERROR", None)
    run = subprocess.run(
        [sys.executable, "-m", "eden_pipe", override, "progress=false"],
        cwd=folder,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    lines = [line for line in run.stderr.splitlines() if line.strip()]
    assert run.returncode == 2 and len(lines) == 1, run.stderr[-2000:]
    assert lines[0] == cli_line(folder, [override, "progress=false"], capsys).replace(f"{folder}/", "")
    assert MESSAGE.match(lines[0]).group(1) == case.key
    assert list(folder.iterdir()) == [], "nothing may be written"


def test_optional_keys_are_described_in_words_whatever_the_annotation_style():
    from eden_pipe.config.keys import describe_key, describe_type

    assert describe_key("render.max_frames") == "null or an integer"
    assert describe_type(int | None) == describe_type(typing.Optional[int]) == "null or an integer"  # noqa: UP045 - both styles
