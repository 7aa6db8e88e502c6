"""No two modules of one of our crates import each other, directly or around a loop
(issue 19: "no module imports form a cycle outside patches/"). A module's imports are the
`crate::NAME` paths in its code (comments, doc links included, are not imports), grouped
ones (`crate::{a, b::c}`) too; a file's module is its top-level name under src/, and
each crate root (lib.rs, main.rs, a file under bin/) is a module of its own that no
`crate::NAME` path names.

The crates are read from the workspace's members, the excluded crates of ours that have
a src/ (not patches/), and wan/ (a workspace of its own), so a crate missing from the
scan, or a scan that finds no file, fails rather than passes."""
import re
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
ROOTS = ("lib", "main", "bin")


def crate_sources():
    """Each crate's src/, by its path from the repository: the main workspace's members,
    its excluded crates outside patches/ that have a src/ (the fuzz crate's one target is
    fuzz_targets/decode.rs, a crate root with no modules), and wan/."""
    workspace = tomllib.loads((REPO / "Cargo.toml").read_text())["workspace"]
    dirs = list(workspace["members"])
    dirs += [d for d in workspace.get("exclude", []) if Path(d).parts[0] != "patches" and (REPO / d / "src").is_dir()]
    dirs.append("wan")
    return {d: REPO / d / "src" for d in dirs}


def imports(text):
    code = "\n".join(line for line in text.splitlines() if not line.lstrip().startswith("//"))
    names = set(re.findall(r"crate::([a-z_0-9]+)", code))
    for group in re.findall(r"crate::\{((?:[^{}]|\{[^{}]*\})*)\}", code):
        depth, cur = 0, ""
        for ch in group + ",":
            depth += ch == "{"
            depth -= ch == "}"
            if depth == 0 and ch == ",":
                if cur.strip():
                    names.add(cur.strip().split("::")[0])
                cur = ""
            else:
                cur += ch
    return names


def module_graph(src):
    """Module -> the modules of the same crate it imports. A crate root is named by its
    file (lib.rs, bin/x.rs): a name with a dot, which no import can name."""
    graph = {}
    for f in src.rglob("*.rs"):
        rel = f.relative_to(src)
        top = rel.parts[0].removesuffix(".rs")
        if top in ROOTS:
            top = "/".join(rel.parts[:2]) if top == "bin" else rel.parts[0]
        graph.setdefault(top, set()).update(imports(f.read_text(errors="replace")))
    return {m: {d for d in deps if d in graph and d != m} for m, deps in graph.items()}


def cycles(graph):
    """Strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []

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
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_the_checker_sees_a_cycle_and_a_grouped_import():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert imports("use crate::{args::RosArgs, error::{A, B}};\n/// [`crate::node`]") == {"args", "error"}


def test_no_module_imports_form_a_cycle():
    crates = crate_sources()
    assert {"msgs", "nodes/serial_node", "libs/ros_plumbing", "wan"} <= set(crates), sorted(crates)
    graphs = {d: module_graph(src) for d, src in crates.items()}
    # every crate was read: at least its root (lib.rs or main.rs) is a module of it
    empty = sorted(d for d, g in graphs.items() if not {"lib.rs", "main.rs"} & set(g))
    assert not empty, f"crates whose src/ has no lib.rs or main.rs: {empty}"
    found = {d: c for d, g in graphs.items() if (c := cycles(g))}
    assert not found, f"module import cycles: {found}"
