"""What a config key allows beyond its type: the domain kinds, and the one error they raise.

A setting is declared once, in its dataclass (``config.schema``), with :func:`setting`: its
default and its domain side by side. A domain checks a value of its key (``check``), says what
is allowed in words (the error message names the key, the value and that), and gives values
of the right type outside it (``outside``: what the tests try for every key). Cross-field rules
are domain kinds too: an :class:`Interval` is two numbers with lo <= hi, :class:`Weights` one
number per entry of a sibling list, and a section's own rules (fractions that sum to one, a
count or a fraction) are declared with :func:`section` on the field that holds the section.

``config.keys.check_values`` walks the schema and calls every domain: there is no check
written case by case. Choices that other tables own (species presets, backends, modalities)
are callables, read when a value is checked, so this module imports none of them.
"""

from __future__ import annotations

import copy
import math
import numbers
import os
import tempfile
import typing
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from eden_pipe.errors import ConfigError

Choices = Sequence[str] | Callable[["Where"], Sequence[str]]


def fail(key: str, value: Any, allowed: str) -> None:
    """The one error of a bad value: ``invalid config: <key>=<value!r>; allowed: <what>``."""
    raise ConfigError(f"invalid config: {key}={value!r}; allowed: {allowed}")


@dataclass(frozen=True)
class Where:
    """Where a value sits: its dotted key, its type annotation and the section object holding it
    (domains over sibling keys read them there)."""

    key: str
    kind: Any
    section: Any

    @property
    def section_key(self) -> str:
        return self.key.rpartition(".")[0]

    @property
    def nullable(self) -> bool:
        return type(None) in typing.get_args(self.kind)

    @property
    def integer(self) -> bool:
        """An ``int`` key, or a list of ints (``Optional`` and ``List`` unwrapped)."""
        kind = self.kind
        while typing.get_args(kind):
            kind = next(a for a in typing.get_args(kind) if a is not type(None))
        return kind is int


class Domain:
    """A key's allowed values (beyond its type, which OmegaConf enforces while composing)."""

    def check(self, value: Any, where: Where) -> None:
        raise NotImplementedError

    def outside(self, where: Where) -> list:
        """Values of the key's type that :meth:`check` rejects (none where every value is allowed)."""
        return []

    def words(self) -> str | None:
        """The values allowed, in words, where the key's type (``Any``) cannot say it."""
        return None


class SectionCheck:
    """A rule over several keys of one section, declared on the field that holds the section."""

    def check(self, section: Any, key: str) -> None:
        raise NotImplementedError

    def outside(self, section: Any) -> list[dict]:
        """Overrides of the section's keys ({leaf: value}) that :meth:`check` rejects."""
        return []

    def words(self, leaf: str) -> str | None:
        """The values the section's key ``leaf`` allows, in words, where its type (``Any``) cannot say it."""
        return None


# ------------------------------------------------------------------ declaring settings
def setting(default: Any, domain: Domain | None = None):
    """A dataclass field: its default and its domain, declared once (lists and mappings copied)."""
    meta = {"domain": domain}
    if isinstance(default, (list, dict)):
        return field(default_factory=lambda: copy.deepcopy(default), metadata=meta)
    return field(default=default, metadata=meta)


def section(cls: type, *checks: SectionCheck, **values: Any):
    """A dataclass field holding a section: ``cls`` with ``values`` over its own defaults, and the
    section's cross-key rules."""
    return field(default_factory=lambda: cls(**copy.deepcopy(values)), metadata={"checks": checks})


def domain_of(f) -> Domain | None:
    return f.metadata.get("domain")


def checks_of(f) -> tuple[SectionCheck, ...]:
    return f.metadata.get("checks", ())


# ------------------------------------------------------------------ numbers
def _is_number(value: Any) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool) and math.isfinite(float(value))


def _bound(value: float, integer: bool) -> str:
    return str(int(value)) if integer else repr(float(value))


@dataclass(frozen=True)
class Number(Domain):
    """A finite number (an integer for ``int`` keys), within the bounds given; ``above``: lo excluded."""

    lo: float | None = None
    hi: float | None = None
    above: bool = False
    note: str = ""  # what a special value means, e.g. "0 = one per core"

    def allowed(self, where: Where, value: Any = 0) -> str:
        """In words; ``value``: the value refused (inf or nan: the words say finite)."""
        finite = _is_number(value) or not isinstance(value, numbers.Real)
        noun = "an integer" if where.integer else "a number" if finite else "a finite number"
        if self.lo is not None and self.hi is not None:
            bounds = f" in {self.lo:g}..{self.hi:g}" if where.integer else f" in [{self.lo:g}, {self.hi:g}]"
        elif self.lo is not None:
            bounds = f" {'>' if self.above else '>='} {self.lo:g}"
        elif self.hi is not None:
            bounds = f" <= {self.hi:g}"
        else:
            bounds = ""
        note = f" ({self.note})" if self.note else ""
        return ("null or " if where.nullable else "") + noun + bounds + note

    def check(self, value: Any, where: Where) -> None:
        if value is None and where.nullable:
            return
        ok = _is_number(value) and (not where.integer or float(value).is_integer())
        if ok and self.lo is not None:
            ok = value > self.lo if self.above else value >= self.lo
        if ok and self.hi is not None:
            ok = value <= self.hi
        if not ok:
            fail(where.key, value, self.allowed(where, value))

    def outside(self, where: Where) -> list:
        cast = int if where.integer else float
        found = [cast(self.lo) if self.above else cast(self.lo - 1)] if self.lo is not None else []
        found += [cast(self.hi + 1)] if self.hi is not None else []
        return found + ([] if where.integer else [math.inf])


@dataclass(frozen=True)
class Interval(Domain):
    """A closed interval ``[lo, hi]``: two numbers with lo <= hi, both within the bounds given."""

    lo: float | None = None
    hi: float | None = None

    def allowed(self, where: Where) -> str:
        kind = "integers" if where.integer else "numbers"
        bounds = ([f">= {_bound(self.lo, where.integer)}"] if self.lo is not None else []) + (
            [f"<= {_bound(self.hi, where.integer)}"] if self.hi is not None else []
        )
        return f"a closed interval [lo, hi] of two {kind} with lo <= hi" + (
            f", both {' and '.join(bounds)}" if bounds else ""
        )

    def check(self, value: Any, where: Where) -> None:
        if not isinstance(value, Sequence) or isinstance(value, str):
            fail(where.key, value, self.allowed(where))
        shown = f"[{', '.join(str(v) for v in value)}]"
        if len(value) != 2 or not all(_is_number(v) for v in value):
            fail(where.key, shown, self.allowed(where))
        lo, hi = value
        if lo > hi or (self.lo is not None and lo < self.lo) or (self.hi is not None and hi > self.hi):
            fail(where.key, shown, self.allowed(where))

    def outside(self, where: Where) -> list:
        cast = int if where.integer else float
        inside = [cast(self.lo if self.lo is not None else 0), cast(self.hi if self.hi is not None else 10)]
        found = [[inside[1] + 1, inside[0]]] if inside[0] <= inside[1] else []  # lo > hi
        found += [[cast(self.lo - 1), inside[1]]] if self.lo is not None else []
        found += [[inside[0], cast(self.hi + 1)]] if self.hi is not None else []
        return found + [[inside[0]]]  # one number, not two


@dataclass(frozen=True)
class Weights(Domain):
    """One non-negative number per entry of the sibling list ``per``, with a positive sum."""

    per: str

    def check(self, value: Any, where: Where) -> None:
        entries = getattr(where.section, self.per)
        weights = list(value) if isinstance(value, Sequence) and not isinstance(value, str) else value
        ok = isinstance(weights, list) and len(weights) == len(entries) and all(_is_number(w) for w in weights)
        if not ok or any(w < 0 for w in weights) or sum(weights) <= 0:
            per = self.per.rstrip("s").replace("_", " ")
            fail(where.key, weights, f"{len(entries)} non-negative numbers (one per {per}) with a positive sum")

    def outside(self, where: Where) -> list:
        n = len(getattr(where.section, self.per))
        return [[1.0] * (n + 1), [0.0] * n]


# ------------------------------------------------------------------ names and choices
def _resolve(choices: Choices, where: Where) -> tuple[str, ...]:
    return tuple(choices(where) if callable(choices) else choices)


def _one_of(allowed: Sequence[str]) -> str:
    return (
        "one of " + ", ".join(str(a) for a in allowed) if allowed else "nothing (no presets are installed for this key)"
    )


@dataclass(frozen=True)
class OneOf(Domain):
    """One of a list of words (a callable: the list is read when a value is checked)."""

    choices: Choices

    def check(self, value: Any, where: Where) -> None:
        allowed = _resolve(self.choices, where)
        if value not in allowed:
            fail(where.key, value, _one_of(allowed))

    def outside(self, where: Where) -> list:
        return ["no_such_choice"]


@dataclass(frozen=True)
class Members(Domain):
    """A list of words from ``choices``; non-empty where ``needed`` (a bool, or a test of the
    section: e.g. a pool that draws instances needs species to draw from)."""

    choices: Choices
    needed: bool | Callable[[Any], bool] = False

    def check(self, value: Any, where: Where) -> None:
        allowed = _resolve(self.choices, where)
        needed = self.needed(where.section) if callable(self.needed) else self.needed
        items = list(value) if isinstance(value, Sequence) and not isinstance(value, str) else None
        bad = [v for v in items if v not in allowed] if items is not None else [value]
        if bad or (needed and not items):
            fail(where.key, bad[0] if bad else items, ("a non-empty list of " if needed else "") + _one_of(allowed))

    def outside(self, where: Where) -> list:
        needed = self.needed(where.section) if callable(self.needed) else self.needed
        return [["no_such_choice"]] + ([[]] if needed else [])


@dataclass(frozen=True)
class AllOrMembers(Domain):
    """The word ``every`` (all the choices), or a list of them (non-empty where ``needed``)."""

    every: str
    what: str  # the choices in words, e.g. "grass presets"
    members: Members

    def words(self) -> str:
        return f"{self.every!r} or a list of {self.what}"

    def check(self, value: Any, where: Where) -> None:
        if value == self.every:
            return
        if isinstance(value, str) or not isinstance(value, Sequence):
            fail(where.key, value, self.words())
        self.members.check(value, where)

    def outside(self, where: Where) -> list:
        return ["everything"] + self.members.outside(where)


@dataclass(frozen=True)
class Name(Domain):
    """A non-empty name that can be part of a folder name (no ``/``)."""

    def check(self, value: Any, where: Where) -> None:
        if not isinstance(value, str) or not value or "/" in value:
            fail(where.key, value, "a non-empty name without '/'")

    def outside(self, where: Where) -> list:
        return ["", "a/b"]


@dataclass(frozen=True)
class MappingOf(Domain):
    """A mapping whose every value is in ``values`` (keys are free: e.g. garden ids)."""

    values: Domain

    def check(self, value: Any, where: Where) -> None:
        if not isinstance(value, typing.Mapping):
            fail(where.key, value, "a mapping")
        for key, item in value.items():
            self.values.check(item, Where(f"{where.key}.{key}", str, where.section))

    def outside(self, where: Where) -> list:
        return [{"some-garden": v} for v in self.values.outside(Where(f"{where.key}.x", str, where.section))]


@dataclass(frozen=True)
class Removed(Domain):
    """A key no longer used, kept so an old config fails with a message saying what replaced it.
    ``instead`` may name ``{section}``, the key's section."""

    instead: str

    def check(self, value: Any, where: Where) -> None:
        if value is not None:
            shown = list(value) if isinstance(value, Sequence) and not isinstance(value, str) else value
            fail(where.key, shown, f"nothing (removed: {self.instead.format(section=where.section_key)})")

    def outside(self, where: Where) -> list:
        return [[1.0, 2.0]]


@dataclass(frozen=True)
class Deprecated(Domain):
    """A key still accepted, with a warning naming its replacement (``use``: may name ``{section}``
    and ``{value}``)."""

    domain: Domain
    use: str

    def check(self, value: Any, where: Where) -> None:
        self.domain.check(value, where)
        if value is not None:
            warnings.warn(
                f"{where.key} is deprecated: use {self.use.format(section=where.section_key, value=value)}",
                FutureWarning,
                stacklevel=2,
            )

    def outside(self, where: Where) -> list:
        return self.domain.outside(where)


# ------------------------------------------------------------------ folders
def nearest_existing(path: Path) -> Path:
    """``path``, or its nearest ancestor that exists."""
    path = Path(os.path.abspath(path))
    while not os.path.lexists(path) and path != path.parent:
        path = path.parent
    return path


@dataclass(frozen=True)
class WritableFolder(Domain):
    """A folder that this process can create files in, or can create: a temporary file is made and
    removed in it, or in its nearest existing parent (so the check never creates the folder)."""

    def check(self, value: Any, where: Where) -> None:
        if not isinstance(value, str) or not value:
            fail(where.key, value, "a folder path (not empty)")
        base = nearest_existing(Path(value))
        if not base.is_dir():
            fail(where.key, value, f"a folder path ({base} exists and is not a folder)")
        try:
            fd, probe = tempfile.mkstemp(prefix=".eden-pipe-write-probe-", dir=base)
            os.close(fd)
            os.unlink(probe)
        except OSError as err:
            fail(where.key, value, f"a folder this user can write (creating a file in {base} failed: {err.strerror})")

    def outside(self, where: Where) -> list:
        return ["", "/proc/eden-pipe-forbidden"]


@dataclass(frozen=True)
class Program(Domain):
    """An executable file, or empty for this interpreter (a key naming the program a backend runs)."""

    def check(self, value: Any, where: Where) -> None:
        if not isinstance(value, str):
            fail(where.key, value, "a path to an executable, or empty for this Python")
        if value and not (os.path.isfile(value) and os.access(value, os.X_OK)):
            fail(where.key, value, "a path to an executable file, or empty for this Python")

    def outside(self, where: Where) -> list:
        return ["/proc/eden-pipe-no-such-program"]


# ------------------------------------------------------------------ rules over a section
@dataclass(frozen=True)
class SumsToOne(SectionCheck):
    """Non-negative fractions (``keys`` of the section) that sum to 1."""

    keys: tuple[str, ...]

    def check(self, section: Any, key: str) -> None:
        values = {k: getattr(section, k) for k in self.keys}
        if any(v < 0 for v in values.values()) or abs(sum(values.values()) - 1.0) > 1e-6:
            fail(key, values, f"non-negative {'/'.join(self.keys)} fractions summing to 1")

    def outside(self, section: Any) -> list[dict]:
        return [{self.keys[0]: getattr(section, self.keys[0]) / 2}]  # each fraction allowed, the sum not


@dataclass(frozen=True)
class AtMostOne(SectionCheck):
    """At most one of ``keys`` set (not null)."""

    keys: tuple[str, ...]
    what: str  # the keys in words, e.g. "a count or a fraction"
    example: tuple  # a value of each key, all allowed alone

    def check(self, section: Any, key: str) -> None:
        values = {k: getattr(section, k) for k in self.keys}
        if sum(v is not None for v in values.values()) > 1:
            fail(key, values, f"{self.what}, not both")

    def outside(self, section: Any) -> list[dict]:
        return [dict(zip(self.keys, self.example, strict=True))]


@dataclass(frozen=True)
class ScenarioLimits(SectionCheck):
    """The lighting section: every key within its scenario's limits (``lighting.SCENARIO_TABLE``,
    checked by ``lighting.check_lighting``, the one lighting check, which direct callers of the
    sky also use)."""

    def check(self, section: Any, key: str) -> None:
        from eden_pipe.lighting import check_lighting

        check_lighting(section)

    def words(self, leaf: str) -> str | None:
        from eden_pipe.lighting import DRAWN_KEYS, WIND_KEYS

        return "a number or [lo, hi] within the scenario's limits" if leaf in DRAWN_KEYS + WIND_KEYS else None

    def outside(self, section: Any) -> list[dict]:
        from eden_pipe.lighting import DRAWN_KEYS, SCENARIO_TABLE, WIND_KEYS

        scenario = SCENARIO_TABLE[section.name]
        beyond = [
            {key: [scenario.limits(key)[0][1] + 1] * 2} if scenario.uses(key) else {key: 0.5} for key in DRAWN_KEYS
        ]  # past the upper limit; a key the scenario leaves unset
        beyond += [{key: [scenario.limits(key)[0][1] + 1] * 2} for key in WIND_KEYS]
        return beyond + [
            {"name": "no_such_scenario"},
            {"environment_sun": "no_such_mode"},
            {"environment": "no_such_map.hdr"},
            {"scenery": "no_such_panorama.png"},
        ]
