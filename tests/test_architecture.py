"""The package dependency direction of docs/architecture.md, checked on the source (static imports)."""

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "vical"

# subpackage -> vical subpackages it must never import
FORBIDDEN = {
    "geometry": {"data", "io", "sim", "calib", "env", "rl", "policies", "apps"},
    "data": {"io", "sim", "calib", "env", "rl", "policies", "apps"},
    "io": {"sim", "calib", "env", "rl", "policies", "apps"},
    "sim": {"calib", "env", "rl", "policies", "apps"},
    "calib": {"sim", "env", "rl", "policies", "apps"},
    "rl": {"sim", "calib", "env", "policies", "apps"},
    "env": {"rl", "policies", "apps"},
    "policies": {"apps"},
    # robot: the arm and sensor interfaces and hardware adapters; the simulated adapters live in sim
    "robot": {"io", "sim", "calib", "env", "rl", "policies", "apps", "parallel"},
    "parallel": {"geometry", "data", "io", "sim", "calib", "env", "rl", "policies", "apps"},  # generic: config only
}


def vical_imports(path: Path) -> set[str]:
    """Second-level vical packages a module imports (``vical.sim.x`` -> ``sim``)."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        names = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [node.module]
        found |= {n.split(".")[1] for n in names if n.startswith("vical.") and n.count(".") >= 1}
    return found


@pytest.mark.parametrize("subpackage", sorted(FORBIDDEN))
def test_subpackage_respects_dependency_direction(subpackage):
    violations = []
    for path in sorted((PACKAGE / subpackage).rglob("*.py")):
        bad = vical_imports(path) & FORBIDDEN[subpackage]
        if bad:
            violations.append(f"{path.relative_to(PACKAGE.parent)} imports vical.{', vical.'.join(sorted(bad))}")
    assert not violations, "\n".join(violations)


def test_checker_sees_imports(tmp_path):
    module = tmp_path / "m.py"
    module.write_text("import vical.sim.robot\nfrom vical.calib import x\nfrom . import y\n")
    assert vical_imports(module) == {"sim", "calib"}
