"""The layers of docs/layout.md, held against the code's own imports.

Every import counts (module level or inside a function); only ``if TYPE_CHECKING:`` blocks are exempt, as they
never run. A package may import only what its row in ``MAY_IMPORT`` names: the layers below it. The table is
the one docs/layout.md draws; a new edge needs a reason written there and a row changed here.
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# the ground floor: every package may use these
BASE = {
    "monitor.errors",
    "monitor.files",
    "monitor.config_file",
    "monitor.cli_logging",
    "monitor.process",
    "monitor.parallel",
}

# the library below the entry points (layers 1-4 of docs/layout.md)
LIBRARY = {
    "monitor.wire",
    "monitor.link",
    "monitor.model",
    "monitor.design",
    "monitor.gains",
    "monitor.checks",
    "monitor.pipelines",
    "monitor.service",
    "monitor.scoring",
}

MAY_IMPORT: dict[str, set[str]] = {
    "monitor.errors": set(),
    "monitor.files": set(),
    "monitor.config_file": set(),
    "monitor.cli_logging": set(),
    "monitor.process": set(),
    "monitor.parallel": set(),
    "monitor.wire": set(),
    "monitor.link": {"monitor.wire"},
    "monitor.model": {"monitor.wire"},
    "monitor.design": {"monitor.wire", "monitor.model"},
    "monitor.gains": {"monitor.wire", "monitor.model", "monitor.design"},
    "monitor.checks": {"monitor.wire", "monitor.model", "monitor.design", "monitor.gains"},
    "monitor.pipelines": {"monitor.wire", "monitor.link", "monitor.model"},
    "monitor.service": {"monitor.wire", "monitor.link", "monitor.model", "monitor.gains"},
    "monitor.scoring": {"monitor.wire", "monitor.model", "monitor.checks", "monitor.service"},
    "monitor.jsbsim_flights": {
        "monitor.wire",
        "monitor.link",
        "monitor.model",
        "monitor.checks",
        "monitor.service",
        "sim_vehicle",
    },
    "monitor.demo": LIBRARY | {"monitor.jsbsim_flights"},
    "monitor.api": LIBRARY | {"monitor.demo", "monitor.jsbsim_flights"},
    "monitor.commands": LIBRARY | {"monitor.demo", "monitor.jsbsim_flights"},
    "monitor.cli": {"monitor.commands"},
    "monitor.__main__": {"monitor.cli"},
    # the vehicle knows the wire and the plant's description, never the estimator or the designs
    "sim_vehicle": {"monitor.wire", "monitor.model.plant"},
}


def unit(module: str) -> str | None:
    """The layer a module belongs to: a sub-package of monitor, a top-level module of monitor, or sim_vehicle."""
    parts = module.split(".")
    if parts[0] == "sim_vehicle":
        return "sim_vehicle"
    if parts[0] != "monitor" or len(parts) == 1:
        return None
    sub = ROOT / "monitor" / parts[1]
    if not (sub.is_dir() or sub.with_suffix(".py").is_file()):
        return None  # a name of the package itself (``from monitor import __version__``)
    return f"monitor.{parts[1]}"


def _type_checking_only(node: ast.AST, parents: dict[ast.AST, ast.AST]) -> bool:
    while node in parents:
        node = parents[node]
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            return True
    return False


def imports() -> dict[tuple[str, str], list[str]]:
    """``(from_unit, imported_module) -> [where]`` over monitor/ and sim_vehicle/."""
    found: dict[tuple[str, str], list[str]] = defaultdict(list)
    for py in sorted([*ROOT.joinpath("monitor").rglob("*.py"), *ROOT.joinpath("sim_vehicle").rglob("*.py")]):
        rel = py.relative_to(ROOT)
        module = ".".join(rel.with_suffix("").parts).removesuffix(".__init__")
        src = unit(module)
        if src is None:  # monitor/__init__.py: lazy re-exports of the public API
            continue
        tree = ast.parse(py.read_text())
        parents = {child: parent for parent in ast.walk(tree) for child in ast.iter_child_nodes(parent)}
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            else:
                continue
            if _type_checking_only(node, parents):
                continue
            for name in names:
                if unit(name) not in (None, src) or (src == "sim_vehicle" and name.startswith("monitor.")):
                    found[(src, name)].append(f"{rel}:{node.lineno}")
    return found


def _allowed(src: str, name: str) -> bool:
    dst = unit(name)
    if dst is None or dst == src or dst in BASE or name == "monitor":
        return True
    allowed = MAY_IMPORT.get(src)
    assert allowed is not None, f"{src} has no row in MAY_IMPORT (and none in docs/layout.md)"
    return dst in allowed or any(name == a or name.startswith(a + ".") for a in allowed)


def test_every_import_points_down_the_layers() -> None:
    wrong = sorted(
        f"{src} -> {name} ({where[0]})" for (src, name), where in imports().items() if not _allowed(src, name)
    )
    assert not wrong, "imports against docs/layout.md:\n" + "\n".join(wrong)


def test_no_two_packages_import_each_other() -> None:
    pairs = {(src, unit(name)) for (src, name) in imports()}
    mutual = sorted({tuple(sorted((a, b))) for a, b in pairs if b and (b, a) in pairs and a != b})
    assert not mutual, mutual


def test_the_monitor_flies_sim_vehicle_from_one_module_only() -> None:
    where = {
        w.split(":")[0]
        for (src, name), ws in imports().items()
        if src.startswith("monitor.") and unit(name) == "sim_vehicle"
        for w in ws
    }
    assert where <= {"monitor/jsbsim_flights.py"}, where


def test_every_layer_is_in_the_docs() -> None:
    text = ROOT.joinpath("docs", "layout.md").read_text()
    missing = [name for name in MAY_IMPORT if f"`{name}`" not in text]
    assert not missing, missing


@pytest.mark.parametrize(
    "src, name",
    [
        ("monitor.design", "monitor.checks.verify"),
        ("monitor.model", "monitor.service.vehicles"),
        ("sim_vehicle", "monitor.model.estimator"),
        ("monitor.demo", "monitor.commands.identify"),
    ],
)
def test_the_rules_refuse_an_upward_import(src: str, name: str) -> None:
    assert not _allowed(src, name)


def test_no_test_module_imports_another() -> None:
    """Helpers two test modules share live in helper modules (``tests/*_files.py``, ``tests/daemons.py``, ...): a
    test module imported by another runs its collection twice and ties the two together."""
    import ast

    offenders = []
    for path in sorted(ROOT.joinpath("tests").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text("utf-8"))):
            names = (
                [node.module or ""]
                if isinstance(node, ast.ImportFrom)
                else [a.name for a in node.names]
                if isinstance(node, ast.Import)
                else []
            )
            offenders += [f"{path.relative_to(ROOT)}: {n}" for n in names if n.split(".")[-1].startswith("test_")]
    assert not offenders, offenders
