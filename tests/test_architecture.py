"""The package dependency direction of docs/architecture.md, checked on the source (static imports).

``ALLOWED`` names, for every unit of vical (a subpackage, or a top-level module such as ``config_checks``), every
unit it may import: any pair it does not list is forbidden, and a new unit fails until it is given its row.
"""

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "vical"

# unit -> the vical units it may import (directly)
ALLOWED = {
    "geometry": set(),  # pure math: nothing of vical
    "config_checks": set(),  # config validation: nothing of vical
    "signals": set(),  # interrupts held across calls that cannot be interrupted cleanly: nothing of vical
    "data": {"geometry"},
    "robot": {"data", "geometry"},  # arm and sensor interfaces, hardware adapters
    "parallel": {"config_checks"},  # generic worker pools
    "io": {"config_checks", "data", "geometry"},
    "calib": {"config_checks", "data", "geometry", "io"},  # calibrates real recordings
    "sim": {"config_checks", "data", "geometry", "robot", "signals"},
    "rl": {"config_checks", "io", "parallel"},  # generic SAC: any gymnasium env
    "env": {"calib", "config_checks", "data", "geometry", "sim"},
    "policies": {"config_checks", "env", "rl"},
    "evaluation": {"calib", "config_checks", "data", "env", "geometry", "io", "parallel", "policies", "sim"},
    "collection": {"calib", "config_checks", "data", "env", "geometry", "io", "policies", "robot"},
    "api": {"calib", "data", "env", "evaluation", "geometry", "policies"},  # the public API's own functions
    "apps": {
        "calib", "collection", "config_checks", "data", "env", "evaluation", "geometry", "io", "parallel",
        "policies", "rl", "robot", "signals", "sim",
    },
}  # fmt: skip

# Rules docs/architecture.md states: the table above must keep them.
NEVER = {
    "geometry": {"config_checks", "robot", "parallel"},
    "data": {"io", "sim", "calib", "env", "rl", "policies"},
    "io": {"robot", "parallel", "sim", "calib", "env", "rl"},
    "calib": {"robot", "parallel", "sim", "env", "rl", "policies"},  # it must calibrate a real sensor's recording
    "sim": {"calib", "env", "rl"},  # a detector is injected where the simulator needs one
    "rl": {"sim", "calib", "env", "policies"},  # it trains any gymnasium env
    "robot": {"io", "sim", "calib", "env", "rl", "policies", "parallel"},  # hardware adapters need no simulator
    "parallel": {"geometry", "data", "io", "sim", "calib", "env", "rl", "policies"},
}
LIBRARY = set(ALLOWED) - {"apps"}  # library code never imports the apps


def module_name(path: Path) -> str:
    parts = path.with_suffix("").relative_to(ROOT).parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def unit_of(module: str) -> str:
    """``vical.sim.panda`` -> ``sim``; ``vical.config_checks`` -> ``config_checks``."""
    return module.split(".")[1]


def imported_modules(path: Path) -> set[str]:
    """The vical modules a file imports (anywhere in it), ``from a import b`` as ``a.b`` when that is a module."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            for alias in node.names:
                sub = f"{node.module}.{alias.name}"
                found.add(sub if (ROOT / (sub.replace(".", "/") + ".py")).is_file() else node.module)
    return {m for m in found if m.startswith("vical.")}


def vical_imports(path: Path) -> set[str]:
    """The vical units a module imports (``vical.sim.x`` -> ``sim``)."""
    return {unit_of(m) for m in imported_modules(path)}


def units() -> dict[str, list[Path]]:
    """Every unit of vical with its modules."""
    out: dict[str, list[Path]] = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.parent == PACKAGE and path.stem == "__init__":
            continue
        out.setdefault(module_name(path).split(".")[1], []).append(path)
    return out


def test_every_unit_has_a_row_and_every_row_a_unit():
    assert set(units()) == set(ALLOWED)
    assert all(ALLOWED[u] <= set(ALLOWED) - {u} for u in ALLOWED)


@pytest.mark.parametrize("unit", sorted(ALLOWED))
def test_unit_imports_only_what_its_row_allows(unit):
    violations = []
    for path in units()[unit]:
        bad = vical_imports(path) - ALLOWED[unit] - {unit}
        if bad:
            violations.append(f"{path.relative_to(ROOT)} imports vical.{', vical.'.join(sorted(bad))}")
    assert not violations, "\n".join(violations)


def test_the_table_keeps_the_stated_rules():
    broken = {u: ALLOWED[u] & NEVER[u] for u in NEVER if ALLOWED[u] & NEVER[u]}
    assert not broken
    assert not [u for u in LIBRARY if "apps" in ALLOWED[u]]


def test_the_units_form_no_cycle():
    done: set[str] = set()

    def visit(unit: str, path: tuple[str, ...]) -> None:
        assert unit not in path, " -> ".join((*path, unit))
        if unit not in done:
            for other in sorted(ALLOWED[unit]):
                visit(other, (*path, unit))
            done.add(unit)

    for unit in sorted(ALLOWED):
        visit(unit, ())


def test_the_modules_form_no_import_cycle():
    """No module imports, directly or through others, a module that imports it (lazy imports inside functions too)."""
    graph = {module_name(p): imported_modules(p) for p in PACKAGE.rglob("*.py")}
    graph = {m: {d for d in deps if d in graph and d != m} for m, deps in graph.items()}
    done: set[str] = set()

    def visit(module: str, path: tuple[str, ...]) -> None:
        assert module not in path, "import cycle: " + " -> ".join((*path[path.index(module) :], module))
        if module not in done:
            for other in sorted(graph[module]):
                visit(other, (*path, module))
            done.add(module)

    for module in sorted(graph):
        visit(module, ())


def test_the_documented_table_is_the_imports():
    """docs/architecture.md's table of direct imports states, for every unit, what its modules import."""
    rows = re.findall(r"^\| ((?:`\w+`(?:, )?)+) \| (.+) \|$", (ROOT / "docs" / "architecture.md").read_text(), re.M)
    documented = {}
    for names, imports in rows:
        listed = set() if imports == "nothing" else set(re.findall(r"`(\w+)`", imports))
        documented |= {name: listed for name in re.findall(r"`(\w+)`", names)}
    actual = {u: set().union(*(vical_imports(p) for p in paths)) - {u} for u, paths in units().items()}
    assert documented == actual


def test_checker_sees_imports(tmp_path):
    module = tmp_path / "m.py"
    module.write_text(
        "import vical.sim.panda\nfrom vical.calib import x\nfrom . import y\nfrom vical.config_checks import z"
    )
    assert vical_imports(module) == {"sim", "calib", "config_checks"}
