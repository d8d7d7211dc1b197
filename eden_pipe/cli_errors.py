"""One line for every way the command line can fail (docs/reliability.md).

- :func:`hydra_error_line`: Hydra's own composition errors (an override of an unknown key,
  a wrong type, a missing config file, an unparsable override, a bad key or value in a
  user's config-group file) as the same one line the config checks give, with the file
  named where the error is in one;
- :func:`with_source`: a ``ConfigError`` about a key that a config-group file (a user's
  own garden file) sets, rather than the command line, names that file;
- :func:`io_error_line`: an ``OSError`` mid-job (disk full, a folder made read-only or removed).
"""

from __future__ import annotations

import errno
import re
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import yaml

from eden_pipe.config import CONF_DIR, describe_key, unknown_key_message


def config_dirs(argv: Iterable[str]) -> list[Path]:
    """The folders config groups are read from: ``--config-dir`` / ``-cd`` first, then ``conf/``."""
    argv = list(argv)
    dirs = [Path(argv[i + 1]) for i, a in enumerate(argv[:-1]) if a in ("--config-dir", "-cd")]
    dirs += [Path(a.split("=", 1)[1]) for a in argv if a.startswith("--config-dir=")]
    return dirs + [CONF_DIR]


def group_file(group_and_name: str, dirs: Iterable[Path]) -> str:
    """``garden/mine`` -> the YAML file Hydra read it from (the first folder that has it)."""
    for folder in dirs:
        path = Path(folder) / f"{group_and_name}.yaml"
        if path.is_file():
            return str(path)
    return f"{group_and_name}.yaml"


def _override_value(key: str, argv: Iterable[str]) -> str | None:
    for arg in reversed(list(argv)):  # the last override of a key is the one that counts
        name, sep, value = arg.lstrip("+~").partition("=")
        if sep and name == key:
            return value
    return None


def hydra_error_line(ex: BaseException, argv: list[str]) -> str | None:
    """One line for a Hydra/OmegaConf error raised while composing the config; None if not one."""
    from hydra.errors import HydraException, MissingConfigException, OverrideParseException
    from omegaconf.errors import OmegaConfBaseException

    if isinstance(ex, yaml.YAMLError):  # a config file that is not YAML
        mark = getattr(ex, "problem_mark", None)
        where = f"{mark.name}:{mark.line + 1}:{mark.column + 1}: " if mark else ""
        return f"{where}invalid YAML: {getattr(ex, 'problem', None) or _first_line(str(ex))}"
    if not isinstance(ex, (HydraException, OmegaConfBaseException)):
        return None
    text = f"{ex}\n{ex.__cause__ or ''}"
    if isinstance(ex, MissingConfigException):
        found = re.search(r"Could not find '([^'/]+)/([^']+)'", text)
        if found and ex.options is not None:
            return (
                f"invalid config: {found.group(1)}={found.group(2)!r} is not a config file of group "
                f"{found.group(1)}; allowed: one of {', '.join(ex.options)}"
            )
    if isinstance(ex, OverrideParseException):
        return f"invalid command line: cannot parse an override ({_first_line(str(ex))}); see README: config keys"
    in_file = re.search(r"^In '([^']+/[^']+)'", text)
    source = f"{group_file(in_file.group(1), config_dirs(argv))}: " if in_file else ""
    full_key = re.search(r"full_key: (\S+)", text)
    if full_key:
        key = full_key.group(1)
        if re.search(r"Key '[^']+' not in|ConfigKeyError|ConfigAttributeError", text):
            value = _override_value(key, argv)
            return source + unknown_key_message(key, value, show_value=value is not None)
        if "does not support deletion" in text:
            return f"invalid config: ~{key} cannot be removed; allowed: set it to another value ({key}=...)"
        value = _override_value(key, argv)
        if value is None:
            shown = re.search(r"Value '(.*?)' of type|value: (.*?)$", text, re.M)
            value = next((g for g in shown.groups() if g is not None), None) if shown else None
        try:
            allowed = describe_key(key)
        except KeyError:
            allowed = _first_line(str(ex.__cause__ or ex))
        return source + f"invalid config: {key}={value}; allowed: {allowed}"  # as typed: not repr'd
    return source + "invalid command line: " + " ".join(str(ex).split())


def _first_line(text: str) -> str:
    return next((line.strip() for line in text.splitlines() if line.strip()), text)


# ------------------------------------------------------------------ which file set a key
def with_source(message: str, config: Any) -> str:
    """``message`` prefixed with the config-group file that sets its key, when a file (not an override
    on the command line) does. ``config`` is the composed config with its ``hydra`` node."""
    found = re.match(r"invalid config: ([\w.]+)=", message)
    if not found:
        return message
    try:
        source = key_source(found.group(1), config)
    except Exception:  # noqa: BLE001 - naming the file is a courtesy: never fail while reporting a failure
        return message
    return f"{source}: {message}" if source else message


def key_source(key: str, config: Any) -> str | None:
    hydra = config.get("hydra") if hasattr(config, "get") else None
    if hydra is None:
        return None
    choices = hydra.runtime.choices
    for override in hydra.overrides.task:
        name = str(override).lstrip("+~").split("=", 1)[0]
        if name in choices:  # garden=mine picks a file: the file sets the keys
            continue
        if key == name or key.startswith(name + "."):
            return None  # set on the command line: the message shows it already
    group, _, rest = key.partition(".")
    choice = choices.get(group)
    if not choice or not rest:
        return None
    dirs = [Path(str(s.path)) for s in hydra.runtime.config_sources if s.schema == "file"]
    return _file_setting(group, str(choice), rest.split("."), dirs, set())


def _file_setting(group: str, name: str, parts: list[str], dirs: list[Path], seen: set) -> str | None:
    """The file of ``group/name`` (or of a default it extends) that sets the key ``parts``."""
    path = group_file(f"{group}/{name}", dirs)
    if path in seen or not Path(path).is_file():
        return None
    seen.add(path)
    data = yaml.safe_load(Path(path).read_text()) or {}
    node = data
    for part in parts:
        node = node.get(part) if isinstance(node, dict) else None
        if node is None:
            break
    if node is not None:
        return path
    for default in data.get("defaults", []) or []:
        if isinstance(default, str) and default != "_self_":
            hit = _file_setting(group, default, parts, dirs, seen)
            if hit:
                return hit
    return None


# ------------------------------------------------------------------ I/O errors mid-job
IO_HINTS = {
    errno.ENOSPC: "the disk is full",
    errno.EDQUOT: "the disk quota is used up",
    errno.EFBIG: "the file is larger than this filesystem or the file-size limit (ulimit -f) allows",
    errno.EROFS: "the filesystem is read-only",
    errno.EACCES: "permission denied",
    errno.EPERM: "permission denied",
    errno.ENOENT: "a folder was removed while the job ran",
    errno.ENOTDIR: "a file stands where a folder goes",
}


def io_error_line(err: OSError, somewhere: str = "a file") -> str:
    where = err.filename or somewhere
    why = f" ({IO_HINTS[err.errno]})" if err.errno in IO_HINTS else ""
    return (
        f"cannot write {where}: {err.strerror or err}{why}; finished frames are kept: "
        f"fix this and rerun the same command to resume"
    )
