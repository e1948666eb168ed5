"""koopguide.mavlink is a lower layer: it imports neither the guidance service nor the simulator."""

from __future__ import annotations

import ast
from pathlib import Path

import koopguide.mavlink

ALLOWED_KOOPGUIDE = ("koopguide.mavlink", "koopguide.config", "koopguide.geodesy")


def imported_modules(path: Path) -> set[str]:
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
    return names


def test_the_mavlink_package_imports_only_lower_layers() -> None:
    files = sorted(Path(koopguide.mavlink.__file__).parent.glob("*.py"))
    assert len(files) >= 8
    for path in files:
        for name in imported_modules(path):
            top = name.split(".")[0]
            assert top != "sitl", f"{path.name} imports {name}"
            if top == "koopguide":
                assert name.startswith(ALLOWED_KOOPGUIDE), f"{path.name} imports {name}"
