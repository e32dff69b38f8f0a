#!/usr/bin/env python3
"""Checks that no two source files import each other, directly or through
others: the files of each Rust crate of the workspace, and the ES modules
of the web client (`web/js`). A cycle means neither file can be read,
tested or changed without the other; the rule and the ways out of one are
in docs/architecture.md ("Layering").

Rust: a file is a module; it depends on every module it names by path
(`crate::a::b`, `super::x`, `self::y`, or `x::…` for a child module `x`),
resolved to the deepest module named, in `use` items and in expressions.
A `use` tree is read whole: each leaf of a group (`use a::{b, c::{d, e}}`,
`pub use child::{A, B}`) and a glob (`use x::*`) name their own path.
Declaring a child (`mod x;`) is not a dependency, nor is a visibility
`pub(in crate::a)` (it names an ancestor as a scope, not an item), so a
parent that only declares and re-exports its children is below them; a
child that needs an item of its parent's file makes a cycle with it if
the parent names the child too. Test modules (`mod tests;`, `#[cfg(test)]` modules, `*_tests.rs`
files and inline `#[cfg(test)] mod … { }` blocks) are left out: they may
use anything. `#[path]` attributes are followed.

JavaScript: the relative specifiers of `import … from`, `export … from`
and `import(…)` in `web/js`.

Prints each cycle and exits 1 when there is one that is not in KNOWN.
Run: `python3 scripts/module_cycles.py`.
"""
import os
import re
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MOD_DECL = re.compile(
    r'((?:#\[[^\]]*\]\s*)*)(?:pub(?:\([^)]*\))?\s+)?mod\s+(\w+)\s*;', re.M)
PATH_IN_ATTRS = re.compile(r'#\[path\s*=\s*"([^"]+)"\]')
REF = re.compile(r'\b(crate|super|self)((?:::\w+)+)')
REL = re.compile(r'(?<![:\w])([a-z_]\w*)((?:::\w+)+)')
USE_ITEM = re.compile(r'\buse\s+([^;]*);')
VISIBILITY_IN = re.compile(r'\bpub\s*\(\s*in\s+[\w:]+\s*\)')
JS_IMPORT = re.compile(
    r'''(?:\bimport\s+(?:[\w*{}\s,]+\s+from\s+)?|\bexport\s+[\w*{}\s,]+\s+from\s+|\bimport\s*\(\s*)['"](\.{1,2}/[^'"]+)['"]''')

# Cycles known and not yet broken, each (where, directory): a cycle whose
# files all lie in a listed directory is reported as known; any other fails
# the check. A listed directory with no cycle left is reported, to be
# removed here: the list only shrinks (it is empty: every cycle fails).
KNOWN: set = set()


def strip_comments(text):
    """Comments out, string literals emptied, except a `#[path = "…"]`
    attribute's, which names a module's file."""
    text = re.sub(r'/\*.*?\*/', '', text, flags=re.S)
    text = re.sub(r'(#\[path\s*=\s*)?"(?:\\.|[^"\\])*"',
                  lambda m: m.group(0) if m.group(1) else '""', text)
    return re.sub(r'//[^\n]*', '', text)


def strip_inline_tests(text):
    """Removes `#[cfg(test)] mod name { … }` blocks (brace-matched)."""
    out = []
    i = 0
    pat = re.compile(r'#\[cfg\(test\)\]\s*(?:#\[[^\]]*\]\s*)*(?:pub(?:\([^)]*\))?\s+)?mod\s+\w+\s*\{')
    while True:
        m = pat.search(text, i)
        if not m:
            out.append(text[i:])
            return ''.join(out)
        out.append(text[i:m.start()])
        depth = 1
        j = m.end()
        while j < len(text) and depth:
            if text[j] == '{':
                depth += 1
            elif text[j] == '}':
                depth -= 1
            j += 1
        i = j


def crate_modules(src_root, root_file):
    """Maps module path tuples to their files, following `mod x;`."""
    modules = {}

    def visit(path, file, dir_for_children):
        modules[path] = file
        text = strip_comments(open(file, encoding='utf-8').read())
        for m in MOD_DECL.finditer(text):
            attrs, name = m.group(1), m.group(2)
            p = PATH_IN_ATTRS.search(attrs)
            if p:
                child = os.path.normpath(os.path.join(os.path.dirname(file), p.group(1)))
            else:
                a = os.path.join(dir_for_children, name + '.rs')
                b = os.path.join(dir_for_children, name, 'mod.rs')
                child = a if os.path.exists(a) else b
            if (not os.path.exists(child) or name == 'tests' or child.endswith('_tests.rs')
                    or '#[cfg(test)]' in attrs):
                continue
            if os.path.basename(child) == 'mod.rs':
                sub = os.path.dirname(child)
            else:
                sub = os.path.join(os.path.dirname(child), os.path.splitext(os.path.basename(child))[0])
            visit(path + (name,), child, sub)

    visit((), root_file, src_root)
    return modules


def resolve(current, kind, segs, modules):
    """The module a reference names: the longest module path it starts with."""
    if kind == 'crate':
        base = ()
    elif kind == 'super':
        base = current[:-1]
        while segs and segs[0] == 'super':
            base = base[:-1]
            segs = segs[1:]
    else:
        base = current
    path = base
    for s in segs:
        if path + (s,) in modules:
            path = path + (s,)
        else:
            break
    return path


def use_paths(tree):
    """The full paths a `use` tree names, one tuple of segments per leaf:
    `a::{b, c::{self, d as e}, f::*}` gives `a::b`, `a::c`, `a::c::d` and
    `a::f` (a glob names its module; a leading `::` is dropped)."""
    tokens = re.findall(r'::|\{|\}|,|\*|\w+', tree)
    pos = [0]

    def peek():
        return tokens[pos[0]] if pos[0] < len(tokens) else None

    def take():
        pos[0] += 1
        return tokens[pos[0] - 1]

    def subtree(prefix):
        segs = list(prefix)
        while True:
            t = peek()
            if t is None or t in (',', '}'):
                return [tuple(segs)]
            if t == '::':
                take()
            elif t == '*':
                take()
                return [tuple(segs)]
            elif t == '{':
                take()
                out = []
                while peek() not in (None, '}'):
                    if peek() == ',':
                        take()
                        continue
                    out.extend(subtree(segs))
                if peek() == '}':
                    take()
                return out
            elif t == 'as':
                take()
                if peek() not in (None, ',', '}'):
                    take()
            elif t == 'self' and segs:
                take()
            else:
                segs.append(take())

    return subtree(())


def rust_edges(modules):
    out = {}
    for path, file in modules.items():
        text = strip_inline_tests(strip_comments(open(file, encoding='utf-8').read()))
        # `pub(in crate::a)` names a scope the item is visible in, always an
        # ancestor: not a dependency
        text = VISIBILITY_IN.sub('pub', text)
        refs = set()
        for m in REF.finditer(text):
            segs = tuple(s for s in m.group(2).split('::') if s)
            refs.add(resolve(path, m.group(1), segs, modules))
        for m in USE_ITEM.finditer(text):
            for segs in use_paths(m.group(1)):
                if not segs:
                    continue
                if segs[0] in ('crate', 'super', 'self'):
                    refs.add(resolve(path, segs[0], segs[1:], modules))
                elif path + (segs[0],) in modules:
                    refs.add(resolve(path, 'self', segs, modules))
        for m in REL.finditer(text):
            if m.group(1) in ('crate', 'super', 'self'):
                continue
            if path + (m.group(1),) in modules:
                segs = (m.group(1),) + tuple(s for s in m.group(2).split('::') if s)
                refs.add(resolve(path, 'self', segs, modules))
        refs.discard(path)
        out[path] = refs
    return out


def strongly_connected(graph):
    """Tarjan's strongly connected components with more than one node."""
    index, low, stack, on, comps = {}, {}, [], set(), []
    counter = [0]
    sys.setrecursionlimit(10000)

    def strong(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in graph:
                continue
            if w not in index:
                strong(w)
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
                comps.append(comp)

    for v in sorted(graph):
        if v not in index:
            strong(v)
    return comps


def rust_cycles():
    crates = []
    for d in sorted(os.listdir(os.path.join(ROOT, 'crates'))):
        src = os.path.join(ROOT, 'crates', d, 'src')
        if os.path.exists(os.path.join(src, 'lib.rs')):
            crates.append((d, src, os.path.join(src, 'lib.rs')))
    crates.append(('dend (binary)', os.path.join(ROOT, 'src'), os.path.join(ROOT, 'src', 'main.rs')))
    found, files = [], 0
    for name, src, root in crates:
        modules = crate_modules(src, root)
        files += len(modules)
        for comp in strongly_connected(rust_edges(modules)):
            names = tuple(sorted(os.path.relpath(modules[p], ROOT) for p in comp))
            found.append((name, names))
    return found, len(crates), files


def js_cycles():
    base = os.path.join(ROOT, 'web', 'js')
    if not os.path.isdir(base):
        return [], 0
    graph = {}
    for dirpath, _, names in os.walk(base):
        for n in names:
            if n.endswith('.js'):
                f = os.path.join(dirpath, n)
                text = re.sub(r'/\*.*?\*/', '', open(f, encoding='utf-8').read(), flags=re.S)
                text = re.sub(r'^\s*//[^\n]*', '', text, flags=re.M)
                deps = set()
                for m in JS_IMPORT.finditer(text):
                    deps.add(os.path.normpath(os.path.join(dirpath, m.group(1))))
                deps.discard(f)
                graph[f] = deps
    found = []
    for comp in strongly_connected(graph):
        found.append(('web/js', tuple(sorted(os.path.relpath(p, ROOT) for p in comp))))
    return found, len(graph)


def main():
    rust, crates, rust_files = rust_cycles()
    js, js_files = js_cycles()
    bad = 0
    seen = set()
    for where, comp in rust + js:
        known = [k for k in KNOWN if k[0] == where and all(f.startswith(k[1]) for f in comp)]
        seen.update(known)
        if known:
            print(f'{where}: known import cycle between {", ".join(comp)}')
        else:
            bad += 1
            print(f'{where}: NEW import cycle between {", ".join(comp)}')
    for where, d in sorted(KNOWN - seen):
        print(f'{where}: no cycle is left in {d}: remove it from KNOWN')
    if bad:
        return 1
    print(f'no new import cycle among the files of {crates} crates ({rust_files} files) '
          f'and web/js ({js_files} files); {len(KNOWN & seen)} known')
    return 0


if __name__ == '__main__':
    sys.exit(main())
