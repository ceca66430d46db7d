"""The layers (docs/architecture.md): every import, inside functions too, flows down; no module imports itself
back through others; no module of fitgen, host or hil is over 500 lines."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
# lowest first: a module may import its own layer and the layers before it
LAYERS = ("fitgen.base", "fitgen.physics", "fitgen.equations", "fitgen.fitting", "fitgen.c", "host", "hil",
          "fitgen.app")
PACKAGES = ("fitgen", "host", "hil")
MAX_LINES = 500


def modules(root: Path) -> dict[str, Path]:
    """Dotted name -> file of every module under the packages."""
    out = {}
    for pkg in PACKAGES:
        for f in (root / pkg).rglob("*.py"):
            parts = f.relative_to(root).with_suffix("").parts
            out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = f
    return out


def layer_of(name: str) -> int | None:
    """Index in LAYERS, or None for a package's root (fitgen/__init__.py: the version, below everything)."""
    for i, layer in reversed(list(enumerate(LAYERS))):
        if name == layer or name.startswith(layer + "."):
            return i
    return None


def imports(name: str, path: Path, known: dict[str, Path]) -> set[str]:
    """The known modules ``name`` imports anywhere in its file (functions included)."""
    is_pkg = path.name == "__init__.py"
    here = name.split(".") if is_pkg else name.split(".")[:-1]
    out = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.ImportFrom):
            base = here[:len(here) - node.level + 1] if node.level else []
            mod = ".".join(base + ([node.module] if node.module else []))
            out |= {c for c in [mod] + [f"{mod}.{a.name}" for a in node.names] if c in known}
        elif isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name in known}
    out.discard(name)
    return out


def violations(root: Path) -> list[str]:
    """Every import that runs up a layer, and every circle of imports, as lines."""
    known = modules(root)
    graph = {n: imports(n, p, known) for n, p in known.items()}
    bad = []
    for n, deps in sorted(graph.items()):
        ln = layer_of(n)
        for d in sorted(deps):
            ld = layer_of(d)
            if ln is not None and ld is not None and ld > ln:
                bad.append(f"{n} ({LAYERS[ln]}) imports {d} ({LAYERS[ld]}), a layer above it")
            if ln is None and ld is not None:
                bad.append(f"{n} (a package's root) imports {d}")
    # circles: depth-first search for a back edge
    state, stack = {}, []

    def visit(n):
        state[n] = 1
        stack.append(n)
        for d in sorted(graph[n]):
            if state.get(d) == 1:
                bad.append("circle: " + " -> ".join(stack[stack.index(d):] + [d]))
            elif d not in state:
                visit(d)
        stack.pop()
        state[n] = 2

    for n in sorted(graph):
        if n not in state:
            visit(n)
    return bad


def test_imports_flow_down_and_close_no_circle():
    assert violations(ROOT) == []


def test_no_module_over_500_lines():
    long = {str(p.relative_to(ROOT)): n for p in modules(ROOT).values()
            if (n := len(p.read_text().splitlines())) > MAX_LINES}
    assert long == {}


def _plant(tmp_path: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        f = tmp_path / rel
        f.parent.mkdir(parents=True, exist_ok=True)
        f.write_text(text)
    for pkg in PACKAGES:
        (tmp_path / pkg).mkdir(exist_ok=True)
        (tmp_path / pkg / "__init__.py").touch()
    return tmp_path


def test_the_check_catches_a_planted_upward_import_inside_a_function(tmp_path):
    root = _plant(tmp_path, {
        "fitgen/physics/__init__.py": "", "fitgen/fitting/__init__.py": "",
        "fitgen/physics/sensor.py": "def f():\n    from fitgen.fitting import fit\n",
        "fitgen/fitting/fit.py": "from ..physics import sensor\n",
        "host/device.py": "from fitgen.physics.sensor import f\n"})
    bad = violations(root)
    assert ("fitgen.physics.sensor (fitgen.physics) imports fitgen.fitting.fit (fitgen.fitting), "
            "a layer above it") in bad
    assert any(b.startswith("circle: ") and "fitgen.fitting.fit" in b for b in bad)
    assert not any("host.device" in b for b in bad)  # host may import the library


def test_the_check_catches_a_library_module_importing_host(tmp_path):
    root = _plant(tmp_path, {"fitgen/c/__init__.py": "", "fitgen/c/codegen.py": "import host.device\n",
                             "host/device.py": ""})
    assert violations(root) == ["fitgen.c.codegen (fitgen.c) imports host.device (host), a layer above it"]
