"""The layering rules of the package, checked on its source (ast, no imports):

* no import cycle inside ``distcloth/``, counting imports inside functions;
* a function-local import only with a comment saying why (a heavy optional
  dependency, or PETSc's start-up order);
* no access to another object's ``_private`` attribute, and no import of
  another module's ``_private`` name;
* MPI only in ``distcloth/parallel/``: no ``mpi4py`` import, no
  communicator collective and no ``COMM_WORLD`` / ``COMM_SELF`` anywhere else.

Each rule is also run on a small bad example, so a checker that finds
nothing is not mistaken for a clean package.
"""
from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "distcloth"

# mpi4py communicator methods that communicate (the wrapper in parallel/comm.py
# gives the rest of the package named operations instead)
MPI_CALLS = {
    "Allreduce", "allreduce", "Bcast", "bcast", "Barrier", "barrier", "Allgather", "allgather",
    "Allgatherv", "Gather", "gather", "Gatherv", "Scatter", "scatter", "Scatterv", "Reduce",
    "Alltoall", "alltoall", "Alltoallv", "Send", "send", "Recv", "recv", "Isend", "isend",
    "Irecv", "irecv", "Issend", "Iprobe", "iprobe", "Ibarrier", "Sendrecv", "sendrecv", "Abort",
    "Split", "Dup", "Get_rank", "Get_size", "Exscan", "Scan",
}
WORLD_NAMES = {"COMM_WORLD", "COMM_SELF"}


def module_name(path: Path, root: Path = PACKAGE) -> str:
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def sources(root: Path = PACKAGE) -> dict[str, tuple[Path, ast.Module, list[str]]]:
    out = {}
    for path in sorted(root.rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        out[module_name(path, root)] = (path, ast.parse(text), text.splitlines())
    return out


def imported_modules(name: str, path: Path, tree: ast.Module, known: set[str]) -> set[str]:
    """The package's modules that ``name`` imports anywhere in its body."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(tree):
        targets = []
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                stem = ".".join(base + ([node.module] if node.module else []))
            else:
                stem = node.module or ""
            # "from .pkg import mod" names a module; "from .mod import f" a module's member
            targets = [f"{stem}.{a.name}" if f"{stem}.{a.name}" in known else stem
                       for a in node.names]
        found.update(t for t in targets if t in known and t != name)
    return found


def import_cycles(mods) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    known = set(mods)
    graph = {m: imported_modules(m, p, t, known) for m, (p, t, _) in mods.items()}
    index, low, stack, on, cycles = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return cycles


def uncommented_local_imports(mods) -> list[str]:
    bad = []
    for name, (path, tree, lines) in mods.items():
        for fn in ast.walk(tree):
            if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            for node in ast.walk(fn):
                if isinstance(node, (ast.Import, ast.ImportFrom)):
                    here = lines[node.lineno - 1]
                    above = lines[node.lineno - 2].strip() if node.lineno > 1 else ""
                    if "#" not in here and not above.startswith("#"):
                        bad.append(f"{path.name}:{node.lineno}: {ast.unparse(node)}")
    return bad


def private_accesses(mods) -> list[str]:
    bad = []
    for name, (path, tree, _) in mods.items():
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and node.attr.startswith("_")
                    and not node.attr.startswith("__")
                    and not (isinstance(node.value, ast.Name) and node.value.id in ("self", "cls"))):
                bad.append(f"{path.name}:{node.lineno}: {ast.unparse(node)}")
            if isinstance(node, ast.ImportFrom):
                for a in node.names:
                    if a.name.startswith("_") and not a.name.startswith("__"):
                        bad.append(f"{path.name}:{node.lineno}: imports {a.name}")
    return bad


def mpi_outside_parallel(mods) -> list[str]:
    bad = []
    for name, (path, tree, _) in mods.items():
        if name.startswith("distcloth.parallel"):
            continue
        for node in ast.walk(tree):
            if isinstance(node, ast.Import) and any(a.name.split(".")[0] == "mpi4py"
                                                    for a in node.names):
                bad.append(f"{path.name}:{node.lineno}: imports mpi4py")
            elif isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "mpi4py":
                bad.append(f"{path.name}:{node.lineno}: imports from mpi4py")
            elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                  and node.func.attr in MPI_CALLS and _names_a_communicator(node.func.value)):
                bad.append(f"{path.name}:{node.lineno}: calls {ast.unparse(node.func)}")
            elif isinstance(node, ast.Attribute) and node.attr in WORLD_NAMES:
                bad.append(f"{path.name}:{node.lineno}: uses {ast.unparse(node)}")
    return bad


def _names_a_communicator(node: ast.expr) -> bool:
    """``comm``, ``self.comm``, ``comm.mpi_comm``, ``MPI.COMM_WORLD``, ``mpi``...:
    a receiver whose last name says it is a communicator (``ax.scatter`` is not)."""
    last = node.attr if isinstance(node, ast.Attribute) else getattr(node, "id", "")
    return "comm" in last.lower() or "mpi" in last.lower()


# ------------------------------------------------------------------ the package

def test_no_import_cycles():
    assert import_cycles(sources()) == []


def test_function_local_imports_say_why():
    assert uncommented_local_imports(sources()) == []


def test_no_access_to_private_attributes():
    assert private_accesses(sources()) == []


def test_mpi_only_in_parallel():
    assert mpi_outside_parallel(sources()) == []


# ------------------------------------------------- the checker finds what it should

BAD = {
    "__init__.py": "",
    "a.py": "from .b import f\n",
    "b.py": "def f():\n    from . import a\n    return a\n",
    "sub/__init__.py": "",
    "sub/c.py": ("from mpi4py import MPI\n"
                 "def g(sim, comm):\n"
                 "    import json\n"
                 "    x = sim._first_forces\n"
                 "    comm.Allreduce(1, 2)\n"
                 "    return MPI.COMM_WORLD\n"),
    "sub/d.py": "from .c import _helper\n",
    "parallel/__init__.py": "",
    "parallel/e.py": ("from mpi4py import MPI\n"
                      "def h(comm):\n"
                      "    # heavy: only when asked\n"
                      "    import json\n"
                      "    return MPI.COMM_WORLD.allgather(1)\n"),
}


def test_the_checker_catches_each_rule(tmp_path):
    root = tmp_path / "distcloth"
    for rel, text in BAD.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)
    mods = sources(root)
    assert import_cycles(mods) == [["distcloth.a", "distcloth.b"]]
    assert uncommented_local_imports(mods) == ["b.py:2: from . import a", "c.py:3: import json"]
    assert private_accesses(mods) == ["c.py:4: sim._first_forces", "d.py:1: imports _helper"]
    assert mpi_outside_parallel(mods) == ["c.py:1: imports from mpi4py",
                                          "c.py:5: calls comm.Allreduce",
                                          "c.py:6: uses MPI.COMM_WORLD"]
