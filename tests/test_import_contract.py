"""The import contract: data flow one way (particles -> magnetics -> cell -> tables -> macro ->
experiments -> studies/bench -> CLI), and no circle of imports.

Every ``import`` of the library is read from the source (module level and inside functions:
a deferred import is still a dependency) and resolved to the project module it names. A module
may import from its own layer and the layers below it, never from a layer above; and no set
of modules may import each other in a circle.
"""
import ast
import collections
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: layers from the bottom: a module may import from its own layer and those below. A prefix
#: names a package or module; the longest matching prefix decides.
LAYERS = (
    ("micro.common",),                                            # validation, errors, files
    ("micro",),                                                   # particle scale
    ("homogenize.voxels",),                                       # the grid, element maths,
                                                                  # kernels, the memory model
    ("homogenize.solvers",),                                      # the solver layer
    ("homogenize.cell",),                                         # cell problems
    ("homogenize.tables",),                                       # batch tables
    ("homogenize",),                                              # the package's public face
    ("homogenize.macro",),                                        # specimen, devices
    ("homogenize.experiments",),                                  # measured data
    ("homogenize.studies", "homogenize.bench"),                   # applications
    ("homogenize.cli",),                                          # the command line
)


def _modules():
    mods = {}
    for pkg in ("micro", "homogenize"):
        for p in (ROOT / pkg).rglob("*.py"):
            name = ".".join(p.relative_to(ROOT).with_suffix("").parts)
            mods[name.removesuffix(".__init__")] = p
    return mods


def _owner(name, mods):
    while name and name not in mods:
        name = name.rpartition(".")[0]
    return name


def _edges(mods):
    edges = collections.defaultdict(set)
    for mod, path in mods.items():
        is_pkg = path.name == "__init__.py"
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            targets = []
            if isinstance(node, ast.Import):
                targets = [_owner(a.name, mods) for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = mod.split(".") if is_pkg else mod.split(".")[:-1]
                    base = base[:len(base) - (node.level - 1)]
                    base = ".".join(base + ([node.module] if node.module else []))
                else:
                    base = node.module
                for a in node.names:
                    sub = f"{base}.{a.name}"
                    targets.append(sub if sub in mods else _owner(base, mods))
            for t in targets:
                if t and t != mod:
                    edges[mod].add(t)
    return edges


def _layer(mod):
    best = None
    for i, prefixes in enumerate(LAYERS):
        for pre in prefixes:
            if (mod == pre or mod.startswith(pre + ".")) and (best is None or len(pre) > best[1]):
                best = (i, len(pre))
    return None if best is None else best[0]


@pytest.fixture(scope="module")
def graph():
    mods = _modules()
    return mods, _edges(mods)


def test_every_module_has_a_layer(graph):
    mods, _ = graph
    assert len(mods) > 50
    assert [m for m in mods if _layer(m) is None] == []


def test_no_import_runs_against_the_flow(graph):
    _, edges = graph
    assert _against(edges) == []


def _against(edges):
    return sorted(f"{a} -> {b} (layer {_layer(a)} imports layer {_layer(b)})"
                  for a, bs in edges.items() for b in bs if _layer(b) > _layer(a))


def _circles(nodes, edges):
    """Tarjan's strongly connected components (iterative): each component of more than one
    module is a circle."""
    index, low, stack, on, circles = {}, {}, [], set(), []
    counter = 0
    for root in nodes:
        if root in index:
            continue
        work = [(root, iter(sorted(edges.get(root, ()))))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(edges.get(w, ())))))
                    break
                if w in on:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on.discard(w)
                        comp.append(w)
                        if w == v:
                            break
                    if len(comp) > 1:
                        circles.append(sorted(comp))
    return circles


def test_the_base_imports_no_project_module(graph):
    """micro.common is the neutral base: validation, errors and files import nothing above."""
    mods, edges = graph
    base = [m for m in mods if m == "micro.common" or m.startswith("micro.common.")]
    assert len(base) >= 5
    assert sorted(f"{a} -> {b}" for a in base for b in edges.get(a, ())
                  if not (b == "micro.common" or b.startswith("micro.common."))) == []


def test_no_circle_of_imports(graph):
    mods, edges = graph
    assert _circles(mods, edges) == []


def test_the_checks_catch_a_violation():
    # a micro module importing the CLI runs against the flow; a -> b -> c -> a is a circle,
    # found next to a module outside it
    edges = {"micro.dipoles": {"homogenize.cli.cmd_macro"}, "homogenize.cell.problem": {"micro.rve"}}
    assert _against(edges) == ["micro.dipoles -> homogenize.cli.cmd_macro (layer 1 imports layer "
                               f"{_layer('homogenize.cli.cmd_macro')})"]
    ring = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert _circles(["d", "a", "b", "c"], ring) == [["a", "b", "c"]]
    assert _circles(["a", "b"], {"a": {"b"}}) == []


def test_one_memory_model():
    """homogenize.voxels._budget is the only place that reads the machine's memory and the only one
    that defines a cell solve's memory estimate (issue 33: one model, one threshold); it sits in
    the lowest layer of homogenize, so that the solvers and the mesh can use it."""
    import re
    readers, estimates = [], []
    for mod, path in _modules().items():
        text = path.read_text(encoding="utf-8")
        if "SC_PHYS_PAGES" in text or "virtual_memory(" in text:
            readers.append(mod)
        if re.search(r"^def \w*(memory|_bytes)\w*\(", text, re.M) and "cell" in text \
                and re.search(r"^def \w*cell\w*bytes\(|^def \w*memory_estimate\w*\(|"
                              r"^def estimate_memory\w*\(", text, re.M):
            estimates.append(mod)
    assert readers == ["homogenize.voxels._budget"]
    assert estimates == ["homogenize.voxels._budget"]
    assert _layer("homogenize.voxels._budget") == _layer("homogenize.voxels") == 2


def test_one_periodic_box():
    """micro.box.PeriodicBox owns the periodic geometry (issue 33: one owner per concern): it
    is the only module that builds a periodic KD-tree (``boxsize=``), and no module defines a
    minimum-image function of its own; the others ask a box. Non-periodic trees (homogenize.macro) are not periodic
    geometry, and the numba kernels repeat the minimum image inline (they cannot call it)."""
    import re
    trees, images = [], []
    for mod, path in _modules().items():
        text = path.read_text(encoding="utf-8")
        if "boxsize" in text:
            trees.append(mod)
        if re.search(r"^def \w*minimum_image\w*\(", text, re.M):
            images.append(mod)
    assert trees == ["micro.box"]
    assert images == []
    assert _layer("micro.box") == _layer("micro.rve")      # below every caller
