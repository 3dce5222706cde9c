"""The floors of the code, checked from its imports.

`common/` is the ground floor: it imports nothing of `services/`, `deploy/` or `bench/`.
A service imports `common/` and its own package, never another service (they talk over
Zenoh only), and never `deploy/` or `bench/`. `deploy/` (the one place that knows every
service) and `bench/` (measuring) sit on top and may import anything below. No module
imports itself back through a chain of top-level imports (an import cycle); an import
inside a function is the way to load a heavy module only when it is used, so it counts
for the floors but not for cycles.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

from common.config import REPO_ROOT

PACKAGES = ("common", "services", "deploy", "bench")


def _modules() -> dict[str, Path]:
    out: dict[str, Path] = {}
    for package in PACKAGES:
        for path in sorted((REPO_ROOT / package).rglob("*.py")):
            parts = path.relative_to(REPO_ROOT).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = path
    return out


MODULES = _modules()


def _imports(module: str, path: Path) -> Iterator[tuple[str, bool]]:
    """(imported module, at top level) for every import of one of ours in `path`."""
    tree = ast.parse(path.read_text(), filename=str(path))
    top = set(map(id, tree.body))
    package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = package[: len(package) - node.level + 1] if node.level else []
            stem = ".".join([*base, *(node.module.split(".") if node.module else [])])
            # `from a import b` imports a.b when b is a module, else a.
            names = [
                f"{stem}.{a.name}" if f"{stem}.{a.name}" in MODULES else stem for a in node.names
            ]
        else:
            continue
        for name in names:
            if name.split(".")[0] in PACKAGES:
                yield _known(name), id(node) in top


def _known(name: str) -> str:
    """The longest prefix of `name` that is one of our modules."""
    parts = name.split(".")
    while parts and ".".join(parts) not in MODULES:
        parts.pop()
    return ".".join(parts) or name


GRAPH = {m: list(_imports(m, p)) for m, p in MODULES.items()}


def _allowed(importer: str, imported: str) -> bool:
    floor, _, rest = importer.partition(".")
    target = imported.split(".")
    if floor == "common":
        return target[0] == "common"
    if floor == "services":
        own = rest.split(".")[0]
        return target[0] == "common" or target[:2] == ["services", own]
    return True  # deploy and bench sit on top


def test_every_import_respects_the_floors() -> None:
    wrong = [
        f"{importer} imports {imported}"
        for importer, imports in GRAPH.items()
        for imported, _ in imports
        if not _allowed(importer, imported)
    ]
    assert not wrong, "\n".join(wrong)


def test_no_import_cycle() -> None:
    edges = {
        m: sorted({i for i, top in imports if top and i != m and i in MODULES})
        for m, imports in GRAPH.items()
    }
    cycles: list[list[str]] = []
    state: dict[str, int] = {}  # 1: on the path, 2: done

    def visit(m: str, path: list[str]) -> None:
        state[m] = 1
        for n in edges[m]:
            if state.get(n) == 1:
                cycles.append([*path[path.index(n) :], n])
            elif n not in state:
                visit(n, [*path, n])
        state[m] = 2

    for m in sorted(edges):
        if m not in state:
            visit(m, [m])
    assert not cycles, "\n".join(" -> ".join(c) for c in cycles)


def test_the_check_sees_a_violation() -> None:
    assert not _allowed("common.bus", "services.sim.world")
    assert not _allowed("services.navigation.node", "services.semantic_map.store")
    assert not _allowed("services.mission.node", "bench.trials")
    assert _allowed("services.mission.node", "services.mission.tree")
    assert _allowed("deploy.cli", "bench.trials")
    assert any(i == "common.bus" for i, _ in GRAPH["deploy.stack"])
