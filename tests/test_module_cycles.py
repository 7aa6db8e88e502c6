"""No two modules of one of our crates import each other, directly or around a loop
(issue 19: "no module imports form a cycle outside patches/"). A module's imports are the
`crate::NAME` paths in its code (comments, doc links included, are not imports), grouped
ones (`crate::{a, b::c}`) too; a file's module is its top-level name under src/."""
import re
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def crate_sources():
    for cargo in sorted(REPO.glob("*/*/Cargo.toml")) + [REPO / "msgs" / "Cargo.toml"]:
        src = cargo.parent / "src"
        if "patches" not in cargo.parts and src.is_dir():
            yield src


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
    graph = {}
    for f in src.rglob("*.rs"):
        top = f.relative_to(src).parts[0].removesuffix(".rs")
        if top in ("lib", "main", "bin"):
            continue
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
    found = {str(src.relative_to(REPO)): c for src in crate_sources() if (c := cycles(module_graph(src)))}
    assert not found, f"module import cycles: {found}"
