"""Every key of the schema, derived from the dataclasses: their names, types and domains, and the
one walk that checks every value (:func:`check_values`)."""

from __future__ import annotations

import dataclasses
import types
import typing
from collections.abc import Iterator
from typing import Any

from eden_pipe.config.domains import Domain, SectionCheck, Where, checks_of, domain_of
from eden_pipe.config.schema import EdenConfig


@dataclasses.dataclass(frozen=True)
class Key:
    """One dotted key of the schema: its type, and its domain (a leaf) or rules (a section)."""

    key: str
    kind: Any
    domain: Domain | None
    checks: tuple[SectionCheck, ...]

    @property
    def section(self) -> type | None:
        return section_type(self.kind)


def schema_fields(cls: type) -> dict[str, Any]:
    """Field name -> its resolved type annotation (a dataclass for nested sections)."""
    hints = typing.get_type_hints(cls)
    return {f.name: hints[f.name] for f in dataclasses.fields(cls)}


def section_type(annotation) -> type | None:
    """The dataclass a field holds (``X`` or ``Optional[X]``); None for a leaf or a free-form value."""
    candidates = [a for a in typing.get_args(annotation) if a is not type(None)] or [annotation]
    for cand in candidates:
        if isinstance(cand, type) and dataclasses.is_dataclass(cand):  # a class (annotations hold no instances)
            return cand
    return None


def join(prefix: str, name: str) -> str:
    return f"{prefix}.{name}" if prefix else name


def schema_items(cls: type | None = None, prefix: str = "") -> Iterator[Key]:
    """Every key of the schema (sections, then their keys), in the order of the dataclasses."""
    cls = cls or EdenConfig
    hints = schema_fields(cls)
    for f in dataclasses.fields(cls):
        item = Key(join(prefix, f.name), hints[f.name], domain_of(f), checks_of(f))
        yield item
        if item.section is not None:
            yield from schema_items(item.section, item.key)


def schema_keys(cls: type | None = None, prefix: str = "") -> list[str]:
    """Every dotted key of the schema (sections and leaves), derived from the dataclasses."""
    return [item.key for item in schema_items(cls, prefix)]


def schema_type(key: str) -> Any:
    """The annotation of the dotted ``key`` in the schema (KeyError if unknown)."""
    cls: Any = EdenConfig
    annotation: Any = None
    for part in key.split("."):
        if cls is None:
            raise KeyError(key)
        annotation = schema_fields(cls)[part]
        cls = section_type(annotation)
    return annotation


def describe_type(annotation) -> str:
    """What a value of a schema type looks like, in words (for error messages)."""
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if annotation is Any:
        return "any value"
    if origin is typing.Union or origin is types.UnionType:  # Optional[X] and X | None
        inner = [a for a in args if a is not type(None)]
        return "null or " + " or ".join(describe_type(a) for a in inner)
    if origin is list:
        return "a list of " + describe_type(args[0]).split(" ", 1)[-1].rstrip("s") + "s" if args else "a list"
    if origin is dict:
        return "a mapping" + (f" {{key: {describe_type(args[1])}}}" if args else "")
    if section_type(annotation) is not None:
        return "a section with the keys " + ", ".join(schema_fields(annotation))
    words = {bool: "true or false", int: "an integer", float: "a number", str: "a string"}
    return words.get(annotation, str(annotation))


def describe_key(key: str) -> str:
    """What the dotted ``key`` allows, in words: its type, or its domain's words where the type is
    ``Any`` (a lighting range, the lawn's species)."""
    items = {item.key: item for item in schema_items()}
    item = items[key]  # KeyError if unknown
    parent, _, leaf = key.rpartition(".")
    words = item.domain.words() if item.domain is not None else None
    words = words or next((w for rule in (items[parent].checks if parent else ()) if (w := rule.words(leaf))), None)
    return words if item.kind is Any and words else describe_type(item.kind)


def check_values(cfg: EdenConfig) -> None:
    """Raise ``ConfigError`` (one line: the key, the value, what is allowed) on the first value outside
    its domain, walking the schema in the order of the dataclasses; a section's rules over several of
    its keys come after those keys."""
    _check_section(cfg, "")


def _check_section(node: Any, prefix: str) -> None:
    hints = schema_fields(type(node))
    for f in dataclasses.fields(node):
        key, value = join(prefix, f.name), getattr(node, f.name)
        if section_type(hints[f.name]) is not None:
            _check_section(value, key)
            for rule in checks_of(f):
                rule.check(value, key)
        elif (domain := domain_of(f)) is not None:
            domain.check(value, Where(key, hints[f.name], node))
