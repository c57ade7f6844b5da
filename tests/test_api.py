"""The package's shape: every module says what it exports, every export is documented, and
imports flow one way through the layers (docs/architecture.md)."""

import ast
import importlib
import inspect
import pkgutil
from pathlib import Path

import pytest

import jbevo

SRC = Path(jbevo.__file__).parent
MODULES = sorted(m.name for m in pkgutil.walk_packages(jbevo.__path__, "jbevo."))

#: What each layer may import besides itself (files and progress are utilities for all).
ALLOWED = {
    "geometry": set(),
    "filtering": {"geometry"},
    "data": {"geometry"},
    "vision": {"geometry", "filtering", "data"},
    "inertial": {"geometry", "filtering", "data"},
    "data.synthetic": {"geometry", "data", "inertial"},
    "data.catalog": {"geometry", "data", "data.synthetic", "inertial"},
    "models": {"geometry", "filtering", "data", "data.synthetic", "vision", "inertial"},
    "eval": {"geometry", "filtering", "data", "vision", "inertial", "models"},
    "training": {"geometry", "filtering", "data", "vision", "inertial", "models", "eval"},
    "cli": {
        "geometry",
        "filtering",
        "data",
        "data.synthetic",
        "data.catalog",
        "vision",
        "inertial",
        "models",
        "eval",
        "training",
    },
    "shim": {"cli"},
}
UTILITIES = {"files", "progress"}
SHIMS = {"train", "evaluate", "localize", "metrics", "demo", "render"}


def layer(module: str) -> str:
    parts = module.split(".")[1:]
    if not parts:
        return "root"
    if parts[0] == "data" and len(parts) > 1 and parts[1] in ("synthetic", "catalog"):
        return f"data.{parts[1]}"
    if len(parts) == 1 and parts[0] in SHIMS:
        return "shim"
    return parts[0]


def imported_modules(path: Path) -> set[str]:
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] == "jbevo":
            if node.module == "jbevo":
                out |= {f"jbevo.{a.name}" for a in node.names}
            else:
                out.add(node.module)
        elif isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name.split(".")[0] == "jbevo"}
    return out


@pytest.mark.parametrize("module", MODULES)
def test_every_module_declares_and_documents_its_exports(module):
    mod = importlib.import_module(module)
    assert mod.__doc__ and mod.__doc__.strip(), f"{module} has no docstring"
    assert hasattr(mod, "__all__"), f"{module} has no __all__"
    for name in mod.__all__:
        assert hasattr(mod, name), f"{module}.__all__ names {name}, which it lacks"
        obj = getattr(mod, name)
        if inspect.isfunction(obj) or inspect.isclass(obj):
            assert inspect.getdoc(obj), f"{module}.{name} has no docstring"


def test_imports_flow_one_way():
    wrong = []
    for path in SRC.rglob("*.py"):
        module = "jbevo." + ".".join(path.relative_to(SRC).with_suffix("").parts)
        module = module.removesuffix(".__init__")
        source = layer(module)
        if source in ("root",) or source in UTILITIES:
            continue
        for target in imported_modules(path):
            target_layer = layer(target)
            if target_layer in (source, *UTILITIES) or target_layer in ALLOWED[source]:
                continue
            wrong.append(f"{module} ({source}) imports {target} ({target_layer})")
    assert not wrong, "\n".join(wrong)


def test_the_top_level_names_the_layers_and_the_main_types():
    for name in ("filtering", "geometry", "vision", "inertial", "models", "data", "eval", "training"):
        assert inspect.ismodule(getattr(jbevo, name))
    for name in ("Bevo", "BevoPlus", "Sequence", "Map", "Camera", "BevGrid", "DPCParams", "register", "run_bevo"):
        assert name in jbevo.__all__ and getattr(jbevo, name) is not None
    assert (SRC / "py.typed").is_file()
