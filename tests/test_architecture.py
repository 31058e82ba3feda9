"""Architecture rules of the ``lumbar`` package, checked on the source of every module:

* no import circle between the package's modules (imports inside function bodies count too);
* no module imports a private name (``_x``) of another ``lumbar`` module, or reaches one through a
  module it imported (``from . import myo_sim`` then ``myo_sim._rot``);
* no library module switches the user's matplotlib backend (``matplotlib.use`` / ``pyplot.switch_backend``).

The modules are found with ``pkgutil.walk_packages`` and imported with ``importlib`` (so every module is also
importable); the graph is built from their source with ``ast``. Dynamic imports
(``importlib.import_module(variable)``) are not seen; the library has none (``lumbar.inputs.tables`` holds its schemas).

The checkers are tested on a tiny fake package, so that each rule can fail.
"""
from __future__ import annotations

import ast
import importlib
import importlib.util
import pkgutil
import re
import sys
import textwrap
from dataclasses import dataclass, field
from pathlib import Path

import networkx as nx
import pytest

import lumbar


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


@dataclass
class ModuleInfo:
    name: str
    path: Path
    is_pkg: bool
    tree: ast.Module = field(repr=False)


def discover_modules(package) -> dict[str, ModuleInfo]:
    """Every module of ``package`` (walk_packages + import_module), with its parsed source."""
    names = [package.__name__] + [m.name for m in pkgutil.walk_packages(package.__path__, package.__name__ + ".")]
    out = {}
    for name in names:
        mod = importlib.import_module(name)
        path = Path(mod.__file__)
        out[name] = ModuleInfo(name, path, path.name == "__init__.py",
                               ast.parse(path.read_text(encoding="utf-8"), filename=str(path)))
    return out


def _resolve(info: ModuleInfo, node: ast.ImportFrom) -> str:
    if not node.level:
        return node.module or ""
    package = info.name if info.is_pkg else info.name.rpartition(".")[0]
    return importlib.util.resolve_name("." * node.level + (node.module or ""), package)


@dataclass
class Analysis:
    graph: nx.DiGraph
    private_imports: list      # (module, line, "target:name")
    backend_switches: list     # (module, line, call)


def analyse(modules: dict[str, ModuleInfo], root: str) -> Analysis:
    """Intra-package import graph (module -> imported module), private-name imports, backend switches."""
    g = nx.DiGraph()
    g.add_nodes_from(modules)
    private, backend = [], []

    def inside(name):
        return name == root or name.startswith(root + ".")

    for info in modules.values():
        aliases: dict[str, str] = {}            # local name -> lumbar module it is bound to
        mpl_names: set[str] = set()             # local names of matplotlib / matplotlib.pyplot / their `use`
        for node in ast.walk(info.tree):
            if isinstance(node, ast.Import):
                for a in node.names:
                    if inside(a.name):
                        target = a.name
                        while target not in modules and "." in target:
                            target = target.rpartition(".")[0]
                        if target in modules and target != info.name:
                            g.add_edge(info.name, target)
                        if a.asname:
                            aliases[a.asname] = a.name
                    elif a.name in ("matplotlib", "matplotlib.pyplot"):
                        mpl_names.add(a.asname or a.name.split(".")[0])
            elif isinstance(node, ast.ImportFrom):
                base = _resolve(info, node)
                if base in ("matplotlib", "matplotlib.pyplot"):
                    mpl_names.update(a.asname or a.name for a in node.names
                                     if a.name in ("use", "switch_backend", "pyplot"))
                if not inside(base):
                    continue
                for a in node.names:
                    sub = f"{base}.{a.name}"
                    if sub in modules:                       # `from . import effects`: the submodule
                        if sub != info.name:
                            g.add_edge(info.name, sub)
                        aliases[a.asname or a.name] = sub
                        if _private(a.name) and sub != info.name:
                            private.append((info.name, node.lineno, sub))
                    else:                                    # `from .effects import EFFECTS`: a name of base
                        if base in modules and base != info.name:
                            g.add_edge(info.name, base)
                            if _private(a.name):
                                private.append((info.name, node.lineno, f"{base}:{a.name}"))
        for node in ast.walk(info.tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and _private(node.attr)
                    and aliases.get(node.value.id, info.name) != info.name):
                private.append((info.name, node.lineno, f"{aliases[node.value.id]}:{node.attr}"))
            if isinstance(node, ast.Call):
                f = node.func
                if isinstance(f, ast.Attribute) and f.attr in ("use", "switch_backend") and (
                        isinstance(f.value, ast.Name) and f.value.id in mpl_names
                        or isinstance(f.value, ast.Attribute) and f.value.attr == "pyplot"):
                    backend.append((info.name, node.lineno, ast.unparse(f)))
                elif isinstance(f, ast.Name) and f.id in mpl_names and f.id in ("use", "switch_backend"):
                    backend.append((info.name, node.lineno, f.id))
    return Analysis(g, private, backend)


def import_cycles(graph: nx.DiGraph, limit: int = 20) -> list[list[str]]:
    """Up to ``limit`` elementary cycles of the import graph, each starting at its smallest module name
    (empty: no circle)."""
    out = []
    for c in nx.simple_cycles(graph):
        k = c.index(min(c))
        out.append(c[k:] + c[:k])
        if len(out) >= limit:
            break
    return sorted(out)


@pytest.fixture(scope="module")
def lumbar_analysis():
    return analyse(discover_modules(lumbar), "lumbar")


# ------------------------------------------------------------------ the package
def test_every_module_is_found_and_imports(lumbar_analysis):
    nodes = set(lumbar_analysis.graph)
    for name in ("lumbar", "lumbar.experiments.effects", "lumbar.experiments.stepwise_reduction", "lumbar.geometry.loader",
                 "lumbar.geometry.visible_human", "lumbar.experiments.l2s1"):
        assert name in nodes
    assert lumbar_analysis.graph.number_of_edges() > 20          # the graph sees the package's imports


def test_no_import_cycle(lumbar_analysis):
    cycles = import_cycles(lumbar_analysis.graph)
    assert not cycles, "import circles (module -> ... -> module):\n" + "\n".join(" -> ".join(c + c[:1])
                                                                               for c in cycles)


def test_no_private_name_of_another_module(lumbar_analysis):
    hits = lumbar_analysis.private_imports
    assert not hits, "private names used across modules:\n" + "\n".join(f"{m}:{ln} uses {t}" for m, ln, t in hits)


def test_library_never_switches_the_matplotlib_backend(lumbar_analysis):
    hits = lumbar_analysis.backend_switches
    assert not hits, "backend switches in the library:\n" + "\n".join(f"{m}:{ln} {c}" for m, ln, c in hits)


#: the subpackages by layer (docs/design.md, "Layers"): a module imports only from its own subpackage and from
#: lower layers; `lumbar` itself (``__version__``) is below all
LAYERS = {
    "lumbar": -1,
    "lumbar.mechanics": 0,
    "lumbar.inputs": 1,
    "lumbar.geometry": 2,
    "lumbar.experiments": 3,
    "lumbar.muscles": 4, "lumbar.plots": 4, "lumbar.report": 4,
    "lumbar.discovery": 5,
    "lumbar.cli": 6,
}


def layer_violations(graph: nx.DiGraph, layers: dict[str, int]) -> list[str]:
    """Edges (module -> module) into a higher or same-layer other subpackage; every module must have a layer."""
    def group(name):
        parts = name.split(".")
        return ".".join(parts[:2]) if len(parts) > 1 else parts[0]

    out = [f"{n}: no layer" for n in graph if group(n) not in layers]
    for u, v in graph.edges:
        gu, gv = group(u), group(v)
        if gu != gv and gu in layers and gv in layers and layers[gv] >= layers[gu]:
            out.append(f"{u} -> {v} (layer {layers[gu]} -> {layers[gv]})")
    return sorted(out)


def test_modules_import_only_from_lower_layers(lumbar_analysis):
    bad = layer_violations(lumbar_analysis.graph, LAYERS)
    assert not bad, "imports against the layers of docs/design.md:\n" + "\n".join(bad)


def test_layer_checker_detects_an_upward_import():
    g = nx.DiGraph([("lumbar.mechanics.model", "lumbar.inputs.io"), ("lumbar.inputs.io", "lumbar.inputs.tables")])
    assert layer_violations(g, LAYERS) == ["lumbar.mechanics.model -> lumbar.inputs.io (layer 0 -> 1)"]
    assert layer_violations(nx.DiGraph([("lumbar.new.x", "lumbar.mechanics.so3")]), LAYERS) == ["lumbar.new.x: no layer"]


DESIGN = Path(__file__).resolve().parents[1] / "docs" / "design.md"


def documented_layers(text: str) -> dict[str, tuple[int, set[str]]]:
    """The "Layers" list of docs/design.md: ``{package: (layer, {module, ...})}`` with full module names. In the list's
    code block a line ``layer N  lumbar.<package>`` opens a package; each of its modules is a line of its own indented
    by two spaces (a nested module by its dotted name); deeper-indented lines continue a description."""
    block = text.split("## Layers", 1)[1].split("```", 2)[1]
    out, current = {}, None
    for line in block.splitlines():
        head = re.match(r"layer (\d+)\s+(lumbar(?:\.\w+)*)\b", line)
        item = re.match(r"  ([A-Za-z_][\w.]*)(?:\s{2,}|$)", line)
        if head:
            current = head.group(2)
            out[current] = (int(head.group(1)), set())
        elif item and current is not None:
            out[current][1].add(f"{current}.{item.group(1)}")
    return out


def layer_list_mismatch(layers: dict[str, tuple[int, set[str]]], modules: set[str]) -> tuple[list, list]:
    """(modules that exist but are not listed, listed names that are no module); ``lumbar`` itself is below all."""
    listed = {"lumbar"} | set(layers) | {m for _, mods in layers.values() for m in mods}
    return sorted(modules - listed), sorted(listed - modules)


def test_design_layer_list_names_every_module_and_no_other():
    modules = {"lumbar"} | {m.name for m in pkgutil.walk_packages(lumbar.__path__, "lumbar.")}
    layers = documented_layers(DESIGN.read_text(encoding="utf-8"))
    missing, extra = layer_list_mismatch(layers, modules)
    assert not missing and not extra, (f"docs/design.md's layer list: not listed {missing}; listed but no module "
                                       f"{extra}")
    # the layer numbers of the list are the ones the layer rule checks
    assert {p: n for p, (n, _) in layers.items()} == {p: n for p, n in LAYERS.items() if p != "lumbar"}


def test_layer_list_check_fails_for_an_unlisted_or_a_vanished_module():
    text = "## Layers\n```\nlayer 0  lumbar.mechanics   the mechanics\n  so3           rotations\n" \
           "                continued: not a module\n  elements.disc   the disc\nlayer 6  lumbar.cli   the command\n```\n"
    layers = documented_layers(text)
    assert layers == {"lumbar.mechanics": (0, {"lumbar.mechanics.so3", "lumbar.mechanics.elements.disc"}),
                      "lumbar.cli": (6, set())}
    modules = {"lumbar", "lumbar.cli", "lumbar.mechanics", "lumbar.mechanics.so3", "lumbar.mechanics.elements.disc"}
    assert layer_list_mismatch(layers, modules) == ([], [])
    # control: a module absent from the list, and a listed module that is gone
    assert layer_list_mismatch(layers, modules | {"lumbar.mechanics.kernel"}) == (["lumbar.mechanics.kernel"], [])
    assert layer_list_mismatch(layers, modules - {"lumbar.mechanics.so3"}) == ([], ["lumbar.mechanics.so3"])


def test_one_effect_registry():
    from lumbar.experiments import effects, stepwise_reduction
    assert "disc_tension" in effects.EFFECTS
    for name in ("EFFECTS", "register_effect", "effect_params"):
        if hasattr(stepwise_reduction, name):                   # a re-export, never a second registry
            assert getattr(stepwise_reduction, name) is getattr(effects, name)
    assert not hasattr(effects, "simulate_stepwise_reduction")


# ------------------------------------------------------------------ the checkers can fail
FAKE = {
    "__init__.py": "",
    "a.py": """
        import matplotlib
        from . import b

        def f():
            from .sub.c import _helper       # private name of another module, inside a function
            matplotlib.use("Agg")
            return _helper
        """,
    "b.py": """
        def g():
            from .sub import c               # b -> sub.c (inside a function)
            return c._hidden()               # private attribute through a module alias
        """,
    "sub/__init__.py": "",
    "sub/c.py": """
        import matplotlib.pyplot as plt

        def _helper():
            from ..a import f                # c -> a: closes a -> b -> c -> a
            plt.switch_backend("Agg")
            return f

        def _hidden():
            return 1
        """,
    "ok.py": """
        from .sub import c
        from . import b as bee
        import fakepkg_arch.sub.c as cc

        def _own():
            return 0

        def h():
            return _own(), c.__name__, bee.g, cc
        """,
}


@pytest.fixture
def fake_package(tmp_path, monkeypatch):
    root = tmp_path / "fakepkg_arch"
    for rel, text in FAKE.items():
        p = root / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(textwrap.dedent(text))
    monkeypatch.syspath_prepend(str(tmp_path))
    yield importlib.import_module("fakepkg_arch")
    for name in [n for n in sys.modules if n == "fakepkg_arch" or n.startswith("fakepkg_arch.")]:
        del sys.modules[name]


def test_cycle_checker_on_a_tiny_graph():
    assert import_cycles(nx.DiGraph([("x", "y"), ("y", "z")])) == []
    assert import_cycles(nx.DiGraph([("x", "y"), ("y", "z"), ("z", "x")])) == [["x", "y", "z"]]


def test_checkers_find_the_faults_of_a_fake_package(fake_package):
    res = analyse(discover_modules(fake_package), "fakepkg_arch")
    assert set(res.graph) == {"fakepkg_arch", "fakepkg_arch.a", "fakepkg_arch.b", "fakepkg_arch.ok",
                              "fakepkg_arch.sub", "fakepkg_arch.sub.c"}
    assert ("fakepkg_arch.b", "fakepkg_arch.sub.c") in res.graph.edges
    assert ("fakepkg_arch.ok", "fakepkg_arch.sub.c") in res.graph.edges
    assert import_cycles(res.graph) == [["fakepkg_arch.a", "fakepkg_arch.b", "fakepkg_arch.sub.c"],
                                        ["fakepkg_arch.a", "fakepkg_arch.sub.c"]]
    assert sorted((m, t) for m, _, t in res.private_imports) == [
        ("fakepkg_arch.a", "fakepkg_arch.sub.c:_helper"), ("fakepkg_arch.b", "fakepkg_arch.sub.c:_hidden")]
    assert sorted(m for m, _, _ in res.backend_switches) == ["fakepkg_arch.a", "fakepkg_arch.sub.c"]


# ------------------------------------------------------------------ lazy imports (lumbar/__init__.py)
#: what the workflow's table, figure and report jobs import (they read results; no mesh, no equilibrium)
RESULT_READERS = ("lumbar.report", "lumbar.report.docs", "lumbar.experiments.validation",
                  "lumbar.experiments.stepwise_reduction", "lumbar.experiments.l2s1", "lumbar.experiments.load_sharing",
                  "lumbar.experiments.admissibility", "lumbar.experiments.fsu", "lumbar.geometry", "lumbar.plots.discovery",
                  "lumbar.plots.stepwise_reduction", "lumbar.plots.load_sharing", "lumbar.plots.validation",
                  "lumbar.plots.l2s1", "lumbar.plots.muscle_model")
#: imported by the functions that build meshes or solve equilibria, never at module level
HEAVY = ("trimesh", "shapely", "scipy.spatial", "numba", "lumbar.mechanics.kernel")


def heavy_imports_of(modules, heavy=HEAVY) -> list[str]:
    """The ``heavy`` modules a fresh interpreter holds after importing ``modules``."""
    import subprocess  # noqa: PLC0415
    code = (f"import sys\nfor m in {list(modules)!r}: __import__(m)\n"
            f"print(' '.join(h for h in {list(heavy)!r} if h in sys.modules))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                       env={**__import__("os").environ, "PYTHONPATH": str(Path(lumbar.__file__).parents[1])})
    assert r.returncode == 0, r.stderr
    return r.stdout.split()


def test_result_readers_import_no_mesh_or_solver_library():
    assert heavy_imports_of(RESULT_READERS) == []


def test_heavy_import_check_sees_a_solver_import():
    # the check can fail: a module that solves (the compiled core) holds numba, one that reads meshes trimesh
    assert set(heavy_imports_of(["lumbar.mechanics.kernel", "lumbar.geometry.landmarks"])) >= \
        {"trimesh", "numba", "lumbar.mechanics.kernel"}


def test_facet_stiffness_is_written_only_by_its_setter():
    """The per-point facet stiffness array is written in one place, ``SpineModel.set_facet_stiffness`` (and its build
    in ``finalize``): an in-place write elsewhere (``m.k_stiff[:] = ...``) is how formulas drift apart."""
    import re
    ROOT = Path(__file__).resolve().parents[1]
    write = re.compile(r"\bk_stiff\s*(\[[^\]]*\])?\s*[-+*/]?=(?!=)")
    offenders = []
    for folder in ("src", "workflow", "benchmarks"):
        for p in (ROOT / folder).rglob("*.py"):
            if p.as_posix().endswith("lumbar/mechanics/model.py"):
                continue
            for i, line in enumerate(p.read_text().splitlines(), 1):
                if write.search(line.split("#")[0]):
                    offenders.append(f"{p.relative_to(ROOT)}:{i}: {line.strip()}")
    assert not offenders, "facet stiffness written outside SpineModel.set_facet_stiffness:\n" + "\n".join(offenders)
    assert write.search("m.k_stiff[:] = k0 * 2") and write.search("model.k_stiff *= 2")   # the pattern finds both
    assert not write.search("k = k_stiff[n]") and not write.search("ok = m.k_stiff == 0")


def test_the_unit_keys_of_the_configuration_are_unpacked_in_one_place():
    """One way from a configuration to a unit: ``lumbar.experiments.fsu.unit_options`` / ``configured_unit`` read the
    stiffness keys of the configuration's ``fsu`` section; no other script or library module reads them from a
    mapping (the report displays the configuration, and two tables have columns of the same name: listed)."""
    import re
    ROOT = Path(__file__).resolve().parents[1]
    keys = ("facet_stiffness_n_per_m", "disc_shear_stiffness_n_per_m")
    read = re.compile(r"""(\.get\(|\[)\s*['"](%s)['"]""" % "|".join(keys))
    allowed = {"src/lumbar/experiments/fsu.py",              # the builder
               "src/lumbar/report/front_sections.py",        # prints the configuration
               "src/lumbar/report/influence_text.py",        # column of the influence table
               "src/lumbar/muscles/muscle_validation.py"}    # column of the chain admissibility table
    offenders = []
    for folder in ("src", "workflow/scripts"):
        for p in (ROOT / folder).rglob("*.py"):
            rel = p.relative_to(ROOT).as_posix()
            if rel in allowed:
                continue
            for i, line in enumerate(p.read_text().splitlines(), 1):
                if read.search(line):
                    offenders.append(f"{rel}:{i}: {line.strip()}")
    assert not offenders, ("configuration unit keys unpacked outside lumbar.experiments.fsu (use configured_unit / "
                           "unit_options):\n" + "\n".join(offenders))
    assert read.search('f.get("facet_stiffness_n_per_m")') and read.search("f['disc_shear_stiffness_n_per_m']")
