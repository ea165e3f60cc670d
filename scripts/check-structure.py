#!/usr/bin/env python3
"""Structure checks that rustc and clippy do not make (docs/ARCHITECTURE.md, "Invariants"):

1. no import cycle between the files of a crate: `use crate::…`, `super::…` and `self::…`
   paths outside test modules and comments, a file's use of its own ancestors not counted
   (a parent declares its children);
2. no non-test function longer than 100 lines.

Prints each violation with its place and exits 1 if there is any. Text-level (no Rust
parser): strings and comments are stripped before braces are counted.
"""
import os
import re
import sys

MAX_FUNCTION_LINES = 100
ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")


def without_tests(text):
    """The text before the first `#[cfg(test)] mod …` block (test modules come last)."""
    match = re.search(r"#\[cfg\(test\)\]\s*(pub(\(crate\))? )?mod \w+\s*\{", text)
    return text[: match.start()] if match else text


def modules(src):
    """Module path -> source text, for every .rs file under a crate's src/."""
    found = {}
    for folder, _, files in os.walk(src):
        for name in files:
            if not name.endswith(".rs"):
                continue
            path = os.path.join(folder, name)
            parts = os.path.relpath(path, src)[:-3].split(os.sep)
            if parts[-1] in ("mod", "lib", "main"):
                parts = parts[:-1]
            with open(path, encoding="utf-8") as f:
                found["::".join(parts) or "crate"] = (path, f.read())
    return found


def import_edges(mods):
    names = set(mods)
    edges = {m: set() for m in mods}
    for module, (_, text) in mods.items():
        code = "\n".join(
            line for line in without_tests(text).split("\n") if not line.strip().startswith("//")
        )
        for match in re.finditer(r"\b((?:crate|super|self)(?:::\w+)+)(?:::\{([^;]*?)\})?", code, re.S):
            paths = [match.group(1)]
            if match.group(2):
                for item in match.group(2).split(","):
                    word = re.match(r"[\w:]+", item.strip())
                    if word:
                        paths.append(match.group(1) + "::" + word.group(0))
            for path in paths:
                target = resolve(path, module, names)
                if target and target != module and target != "crate" and not module.startswith(target + "::"):
                    edges[module].add(target)
    return edges


def resolve(path, module, names):
    segments = path.split("::")
    here = [] if module == "crate" else module.split("::")
    if segments[0] == "crate":
        base, segments = [], segments[1:]
    elif segments[0] == "super":
        base, segments = here[:-1], segments[1:]
        while segments and segments[0] == "super":
            base, segments = base[:-1], segments[1:]
    else:
        base, segments = here, segments[1:]
    for length in range(len(segments), 0, -1):
        candidate = "::".join(base + segments[:length])
        if candidate in names:
            return candidate
    return None


def cycles(edges):
    """Strongly connected components of more than one file (Tarjan)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []
    counter = [0]
    sys.setrecursionlimit(10000)

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in edges[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return found


def long_functions(path, text):
    lines = without_tests(text).split("\n")
    for start, line in enumerate(lines):
        match = re.match(r"\s*(pub(\([a-z]+\))? )?(async )?(const )?(unsafe )?fn (\w+)", line)
        if not match:
            continue
        depth, opened = 0, False
        for end in range(start, len(lines)):
            code = re.sub(r'"([^"\\]|\\.)*"', "", lines[end])
            code = re.sub(r"'([^'\\]|\\.)'", "", code)
            code = re.sub(r"//.*", "", code)
            for c in code:
                if c == "{":
                    depth, opened = depth + 1, True
                elif c == "}":
                    depth -= 1
            if opened and depth == 0:
                break
            if not opened and code.rstrip().endswith(";"):
                break
        length = end - start + 1
        if length > MAX_FUNCTION_LINES:
            yield f"{path}:{start + 1}: fn {match.group(6)} has {length} lines (at most {MAX_FUNCTION_LINES})"


def main():
    problems = []
    crates = os.path.join(ROOT, "crates")
    for crate in sorted(os.listdir(crates)):
        src = os.path.join(crates, crate, "src")
        if not os.path.isdir(src):
            continue
        mods = modules(src)
        edges = import_edges(mods)
        for component in cycles(edges):
            links = "; ".join(f"{m} -> {', '.join(sorted(e for e in edges[m] if e in component))}" for m in component)
            problems.append(f"crates/{crate}: import cycle between {', '.join(component)} ({links})")
        for path, text in mods.values():
            problems.extend(long_functions(os.path.relpath(path, ROOT), text))
    for problem in problems:
        print(problem)
    print(f"structure: {len(problems)} problems" if problems else "structure: no import cycles, no function over 100 lines")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
