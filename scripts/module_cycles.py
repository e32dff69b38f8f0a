#!/usr/bin/env python3
"""Checks that no crate of the workspace has an import cycle between its
modules, and that no two files of the web client (`web/js`) import each
other, directly or around a loop: for every module, the modules it declares (with
everything below them) may use one another only along a directed acyclic
graph. A child using its ancestors' items (`super::`, `crate::` a parent)
is not a cycle: the parent owns the child. Test modules (`mod tests;`
and `*_tests.rs` files) are left out: they may use anything.

Reads `use`/path references (`crate::a::b`, `super::x`, `self::y`)
in the source text; `#[path]` attributes are followed. In `web/js`, every
relative `import`/`export … from` (static or `import('…')`) is an edge
between files. Prints each cycle and exits 1 when there is one. Run: `python3 scripts/module_cycles.py`.
"""
import os
import re
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MOD_DECL = re.compile(r'^\s*(?:#\[path\s*=\s*"([^"]+)"\]\s*)?(?:pub(?:\([^)]*\))?\s+)?mod\s+(\w+)\s*;', re.M)
PATH_ATTR = re.compile(r'#\[path\s*=\s*"([^"]+)"\]\s*(?:#\[[^\]]*\]\s*)*(?:pub(?:\([^)]*\))?\s+)?mod\s+(\w+)\s*;')
# inline `mod x { ... }` test modules are part of their file's module
REF = re.compile(r'\b(crate|super|self)((?:::\w+)+)')
USE_GROUP = re.compile(r'\buse\s+(crate|super|self)::\{([^;]*)\};', re.S)


# Cycles known and not yet broken, each a sorted list of the
# modules in it. A cycle not listed fails the check, and so does a listed
# one that is gone (remove it here): the list only shrinks. Empty since the
# selection types moved to mesh::selection and the coarse levels' type to
# deform::rest.
KNOWN = set()


def strip_comments(text):
    text = re.sub(r'/\*.*?\*/', '', text, flags=re.S)
    return re.sub(r'//[^\n]*', '', text)


def crate_modules(src_root, root_file):
    """Maps module path tuples to their files, following `mod x;`."""
    modules = {}

    def visit(path, file, dir_for_children):
        modules[path] = file
        text = open(file, encoding='utf-8').read()
        declared = {}
        for m in PATH_ATTR.finditer(text):
            declared[m.group(2)] = os.path.normpath(os.path.join(os.path.dirname(file), m.group(1)))
        for m in MOD_DECL.finditer(strip_comments(text)):
            name = m.group(2)
            if name in declared:
                child = declared[name]
            else:
                a = os.path.join(dir_for_children, name + '.rs')
                b = os.path.join(dir_for_children, name, 'mod.rs')
                child = a if os.path.exists(a) else b
            # test modules (`mod tests;`, `*_tests.rs`) are not part of
            # the library's layering
            if not os.path.exists(child) or name == 'tests' or child.endswith('_tests.rs'):
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


def edges(modules):
    out = {}
    for path, file in modules.items():
        text = strip_comments(open(file, encoding='utf-8').read())
        refs = set()
        for m in REF.finditer(text):
            segs = tuple(s for s in m.group(2).split('::') if s)
            refs.add(resolve(path, m.group(1), segs, modules))
        for m in USE_GROUP.finditer(text):
            for item in re.split(r'[,{}\s]+', m.group(2)):
                head = item.split('::')[0] if item else ''
                if head and head not in ('self', 'super', 'crate'):
                    refs.add(resolve(path, m.group(1), tuple(item.split('::')), modules))
        out[path] = refs
    return out


def cycles(modules, uses):
    """Cycles among the children of each module, edges lifted to them."""
    found = []
    for parent in modules:
        kids = [p for p in modules if len(p) == len(parent) + 1 and p[:len(parent)] == parent]
        if len(kids) < 2:
            continue
        graph = {k: set() for k in kids}
        for src, refs in uses.items():
            if src[:len(parent)] != parent or len(src) <= len(parent):
                continue
            a = src[:len(parent) + 1]
            for dst in refs:
                if dst[:len(parent)] == parent and len(dst) > len(parent):
                    b = dst[:len(parent) + 1]
                    if a != b:
                        graph[a].add(b)
        # Tarjan's strongly connected components
        index, low, stack, on, comps = {}, {}, [], set(), []
        counter = [0]

        def strong(v):
            index[v] = low[v] = counter[0]
            counter[0] += 1
            stack.append(v)
            on.add(v)
            for w in graph[v]:
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

        for k in kids:
            if k not in index:
                strong(k)
        for comp in comps:
            names = sorted('::'.join(c) for c in comp)
            found.append(names)
    return found


JS_IMPORT = re.compile(
    r"""(?:\bimport\s*(?:[\w*{}\s,$]+?\s*from\s*)?|\bexport\s*[\w*{}\s,$]+?\s*from\s*|\bimport\s*\(\s*)['"]([^'"]+)['"]""")


def js_cycles(folder):
    """Import cycles between the ES modules under `folder` (each a sorted
    list of paths relative to the repository), and the number of files."""
    files = []
    for d, dirs, names in os.walk(folder):
        dirs[:] = [x for x in dirs if x != 'node_modules']
        files += [os.path.join(d, n) for n in names if n.endswith(('.js', '.mjs'))]
    graph = {}
    for f in files:
        text = open(f, encoding='utf-8').read()
        text = re.sub(r'/\*.*?\*/', '', text, flags=re.S)
        text = re.sub(r'(^|[^:\\])//[^\n]*', r'\1', text)
        graph[f] = set()
        for m in JS_IMPORT.finditer(text):
            spec = m.group(1)
            if spec.startswith('.'):
                target = os.path.normpath(os.path.join(os.path.dirname(f), spec))
                if target in files or os.path.exists(target):
                    graph[f].add(target)
    index, low, stack, on, found = {}, {}, [], set(), []
    counter = [0]

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
            # a file importing itself is a cycle too
            if len(comp) > 1 or v in graph[v]:
                found.append(sorted(os.path.relpath(c, ROOT) for c in comp))

    for f in sorted(graph):
        if f not in index:
            strong(f)
    return found, len(files)


def main():
    crates = []
    for d in sorted(os.listdir(os.path.join(ROOT, 'crates'))):
        src = os.path.join(ROOT, 'crates', d, 'src')
        if os.path.exists(os.path.join(src, 'lib.rs')):
            crates.append((d, src, os.path.join(src, 'lib.rs')))
    crates.append(('dend (binary)', os.path.join(ROOT, 'src'), os.path.join(ROOT, 'src', 'main.rs')))
    bad = 0
    total = 0
    seen = set()
    for name, src, root in crates:
        modules = crate_modules(src, root)
        total += len(modules)
        for comp in cycles(modules, edges(modules)):
            key = (name, tuple(comp))
            seen.add(key)
            if key in KNOWN:
                print(f'{name}: known import cycle between {", ".join(comp)}')
            else:
                bad += 1
                print(f'{name}: NEW import cycle between {", ".join(comp)}')
    for name, comp in sorted(KNOWN - seen):
        bad += 1
        print(f'{name}: the cycle between {", ".join(comp)} is gone: remove it from KNOWN')
    web, nweb = js_cycles(os.path.join(ROOT, 'web', 'js'))
    for comp in web:
        bad += 1
        print(f'web/js: import cycle between {", ".join(comp)}')
    if bad:
        return 1
    print(f'no new import cycle among the modules of {len(crates)} crates ({total} modules); {len(KNOWN)} known; '
          f'none among the {nweb} files of web/js')
    return 0


if __name__ == '__main__':
    sys.exit(main())
