"""The repository keeps its shape: the package's import layers (docs/architecture.md, "Layers"),
modules of at most 600 lines, and comments that cite the repository's own documents."""

from __future__ import annotations

import ast
import io
import re
import tokenize
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGE = "eden_pipe"
ARCHITECTURE = REPO / "docs" / "architecture.md"
SOURCE_FOLDERS = (PACKAGE, "tests", "scripts", "benchmarks")
MAX_LINES = 600


# ------------------------------------------------------------------ layers
@dataclass(frozen=True)
class Import:
    importer: str  # module name without the package prefix, e.g. "render.view"
    imported: str
    line: int
    lazy: bool  # inside a function: runs when called, not when the importer is imported


def module_name(path: Path) -> str:
    parts = list(path.relative_to(REPO / PACKAGE).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def package_modules() -> dict[str, Path]:
    """Every module of the package by name ("" is the package's own __init__)."""
    return {module_name(p): p for p in sorted((REPO / PACKAGE).rglob("*.py"))}


def _resolve(name: str, modules: dict[str, Path]) -> str | None:
    """The package module ``name`` (dotted, without the package prefix) is or lies in; None outside the package."""
    parts = name.split(".")
    while parts:
        candidate = ".".join(parts)
        if candidate in modules:
            return candidate
        parts.pop()
    return None


def _type_checking_block(node: ast.AST) -> bool:
    return isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)


def imports_of(name: str, path: Path, modules: dict[str, Path]) -> list[Import]:
    """The package modules ``name`` imports: at import time, or lazily inside functions. Imports under
    ``if TYPE_CHECKING:`` are left out: they never run, they only name types for annotations."""
    found: list[Import] = []
    package_path = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]

    def visit(node: ast.AST, lazy: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if _type_checking_block(child):
                continue
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                visit(child, True)
                continue
            targets: list[str] = []
            if isinstance(child, ast.Import):
                targets = [alias.name for alias in child.names]
            elif isinstance(child, ast.ImportFrom):
                if child.level:  # relative: from the importer's package
                    base = package_path[: len(package_path) - (child.level - 1)]
                    source = ".".join([PACKAGE, *base, *([child.module] if child.module else [])])
                else:
                    source = child.module or ""
                # "from a import b" imports the module a.b when there is one, else a name of a.
                targets = [f"{source}.{alias.name}" for alias in child.names]
            for target in targets:
                if target == PACKAGE or target.startswith(PACKAGE + "."):
                    imported = _resolve(target.removeprefix(PACKAGE).lstrip("."), modules)
                    if imported and imported != name:
                        found.append(Import(name, imported, child.lineno, lazy))
            visit(child, lazy)

    visit(ast.parse(path.read_text(), str(path)), False)
    return found


@dataclass(frozen=True)
class Layers:
    order: list[list[str]]  # lowest first: each layer's modules or subpackages
    allowed_upward: dict[tuple[str, str], str]  # lazy (importer, imported) imports allowed upward, with why

    def layer_of(self, module: str) -> int | None:
        """The index of the layer whose most specific entry holds ``module`` (an entry holds itself and its
        submodules); None if no entry does."""
        best: tuple[int, int] | None = None  # (entry length, layer)
        for index, entries in enumerate(self.order):
            for entry in entries:
                if (module == entry or module.startswith(entry + ".")) and (best is None or len(entry) > best[0]):
                    best = (len(entry), index)
        return None if best is None else best[1]


def read_layers(text: str) -> Layers:
    """Parse the "Layers" section: a numbered list (lowest first) whose items start with the layer's
    modules in backticks, and a bulleted list of allowed upward lazy imports, "- `a` -> `b`: why"."""
    match = re.search(r"^## Layers\n(.*?)(?=^## |\Z)", text, re.M | re.S)
    assert match, f"{ARCHITECTURE.relative_to(REPO)} has no '## Layers' section"
    section = match.group(1)
    order = []
    for item in re.finditer(r"^\d+\.\s+(.*)$", section, re.M):
        head = re.match(r"((?:`[\w.]+`(?:,\s*)?)+)", item.group(1))
        assert head, f"a layer line must start with its modules in backticks: {item.group(0)!r}"
        order.append(re.findall(r"`([\w.]+)`", head.group(1)))
    allowed = {
        (a, b): why.strip() for a, b, why in re.findall(r"^-\s+`([\w.]+)`\s*->\s*`([\w.]+)`:\s*(.+)$", section, re.M)
    }
    assert order, "the Layers section lists no layer"
    return Layers(order, allowed)


@pytest.fixture(scope="module")
def layers() -> Layers:
    return read_layers(ARCHITECTURE.read_text())


@pytest.fixture(scope="module")
def all_imports() -> list[Import]:
    modules = package_modules()
    return [imp for name, path in modules.items() for imp in imports_of(name, path, modules)]


def test_every_module_has_a_layer(layers):
    unplaced = [name for name in package_modules() if name and layers.layer_of(name) is None]
    assert not unplaced, f"modules in no layer of docs/architecture.md: {unplaced}"
    entries = [entry for layer in layers.order for entry in layer]
    assert len(entries) == len(set(entries)), f"an entry is in two layers: {entries}"
    missing = [entry for entry in entries if entry not in package_modules()]
    assert not missing, f"layer entries that name no module or subpackage: {missing}"


def test_no_module_imports_from_a_higher_layer(layers, all_imports):
    """A module imports from its own layer and the layers below it; a function-level import may reach
    up only where the Layers section allows it and says why."""
    upward = []
    for imp in all_imports:
        own, other = layers.layer_of(imp.importer), layers.layer_of(imp.imported)
        if own is None or other is None or other <= own:
            continue
        if imp.lazy and (imp.importer, imp.imported) in layers.allowed_upward:
            continue
        kind = "in a function" if imp.lazy else "at import time"
        upward.append(
            f"{imp.importer} (layer {own + 1}) imports {imp.imported} (layer {other + 1}) {kind}, line {imp.line}"
        )
    assert not upward, "imports from a higher layer:\n" + "\n".join(upward)


def test_allowed_upward_imports_are_lazy_and_still_there(layers, all_imports):
    """Each allowed exception is a function-level import the code still makes, and really upward."""
    for (importer, imported), why in layers.allowed_upward.items():
        made = [imp for imp in all_imports if (imp.importer, imp.imported) == (importer, imported)]
        assert made, f"allowed upward import {importer} -> {imported} is no longer made: drop it from the list"
        assert all(imp.lazy for imp in made), f"{importer} -> {imported} is allowed lazily only, not at import time"
        assert layers.layer_of(importer) < layers.layer_of(imported), f"{importer} -> {imported} is not upward"
        assert why, f"{importer} -> {imported}: say why it is allowed"


def test_the_layer_check_sees_lazy_and_relative_imports(tmp_path):
    """The scanner itself: lazy, relative and TYPE_CHECKING imports are told apart."""
    package = tmp_path / "pkg"
    (package / "sub").mkdir(parents=True)
    source = (
        "from typing import TYPE_CHECKING\n"
        f"from {PACKAGE}.render import view\n"
        "from . import sibling\n"
        "if TYPE_CHECKING:\n"
        f"    from {PACKAGE}.stages import cache\n"
        "def f():\n"
        f"    import {PACKAGE}.pipeline\n"
    )
    path = package / "sub" / "mod.py"
    path.write_text(source)
    modules = {
        "render.view": Path(),
        "stages.cache": Path(),
        "pipeline": Path(),
        "render.sibling": Path(),
        "render.mod": path,
    }
    got = {(imp.imported, imp.lazy) for imp in imports_of("render.mod", path, modules)}
    assert got == {("render.view", False), ("render.sibling", False), ("pipeline", True)}


# ------------------------------------------------------------------ sizes
def source_files() -> list[Path]:
    return sorted(p for folder in SOURCE_FOLDERS for p in (REPO / folder).rglob("*.py"))


def test_no_source_file_exceeds_600_lines():
    long = {str(p.relative_to(REPO)): n for p in source_files() if (n := len(p.read_text().splitlines())) > MAX_LINES}
    assert not long, f"files over {MAX_LINES} lines (split them by responsibility): {long}"


# ------------------------------------------------------------------ comments
# Comments cite the repository's documents (docs/*.md, README.md), never issue numbers or a design
# document outside the repository.
FOREIGN_CITATION = re.compile(r"\b[Ii]ssues?\s*#?\d+|\bDESIGN(?:\.md)?\s+sections?\b|\bDESIGN\.md\b")


def comments_and_docstrings(path: Path) -> list[tuple[int, str]]:
    text = path.read_text()
    found = [
        (tok.start[0], tok.string)
        for tok in tokenize.generate_tokens(io.StringIO(text).readline)
        if tok.type == tokenize.COMMENT
    ]
    for node in ast.walk(ast.parse(text, str(path))):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            doc = ast.get_docstring(node, clean=False)
            if doc is not None:
                found.append((node.body[0].lineno, doc))
    return found


def test_no_comment_cites_an_issue_or_an_outside_design_document():
    cited = [
        f"{p.relative_to(REPO)}:{line + text[: m.start()].count(chr(10))}: {m.group(0)!r}"
        for p in source_files()
        for line, text in comments_and_docstrings(p)
        for m in FOREIGN_CITATION.finditer(text)
    ]
    assert not cited, "cite docs/*.md instead of issues or DESIGN sections:\n" + "\n".join(cited)


def test_the_citation_check_catches_what_it_should():
    hits = [
        bool(FOREIGN_CITATION.search(s))
        for s in (
            "# issue 16",
            "(Issue 14's numbers)",
            "DESIGN section 4",
            "DESIGN sections 2-5",
            "see DESIGN.md",
            "# see docs/design.md",
            "meet at the corners by design",
            "the issues below",
            "# docs/realism.md section 3",
        )
    ]
    assert hits == [True, True, True, True, True, False, False, False, False]
