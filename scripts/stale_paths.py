#!/usr/bin/env python3
"""Checks that every repository path cited in the docs and in source
comments exists: a reader sent to a file that was moved or deleted is
lost. Cited paths are
- words starting with a top-level directory of the repository
  (`crates/server/src/lease.rs`, `docs/deployment.md`, `scripts/test.sh`),
  which must exist as written, relative to the root;
- other words ending in a source or doc extension (`store/memory.rs`,
  `actor_queue.rs`), which some file of the repository must end with;
- relative Markdown links in `.md` files, resolved from the file.
Read in: `*.md` everywhere, and the comments of `*.rs`, `*.js`, `*.py`,
`*.sh` and `*.yaml` files. Prints each stale path with where it is cited
and exits 1 when there is one. Run: `python3 scripts/stale_paths.py`.
"""
import os
import re
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXTS = ('rs', 'md', 'py', 'sh', 'js', 'yaml', 'yml', 'toml', 'html', 'css')
WORD = re.compile(r'(?<![\w./:-])((?:\.{1,2}/)?[\w.-]+(?:/[\w.-]+)*\.(?:' + '|'.join(EXTS) + r'))\b(?![/\w])')
DIR_WORD = re.compile(r'(?<![\w./:-])((?:crates|docs|scripts|tests|src|web|api|clients|benches|examples|fuzz|docker|\.ci)/[\w./-]*[\w/])')
MD_LINK = re.compile(r'\]\(([^)#\s]+)(?:#[^)]*)?\)')
# Stale citations known and not yet fixed, (file, path): reported, not
# failing; the list only shrinks.
KNOWN: set = set()
# names that are not paths of this repository (other projects' files,
# files a program writes, placeholders)
NOT_OURS = {'three.js', 'three.module.js'}


def ignored(path):
    """Whether git ignores `path` (a directory or file a program writes)."""
    for p in (path, path.rstrip('/') + '/'):
        r = subprocess.run(['git', 'check-ignore', '-q', '--no-index', p], cwd=ROOT)
        if r.returncode == 0:
            return True
    return False


def tracked():
    out = subprocess.run(['git', 'ls-files'], cwd=ROOT, capture_output=True, text=True, check=True)
    return [l for l in out.stdout.splitlines() if l]


def comments(path, text):
    if path.endswith('.md'):
        # code blocks too: commands and file names in them are cited
        return text
    if path.endswith(('.py', '.sh', '.yaml', '.yml', '.toml')):
        return '\n'.join(m.group(0) for m in re.finditer(r'#[^\n]*', text)) + '\n' + \
            '\n'.join(m.group(0) for m in re.finditer(r'"""(.*?)"""', text, re.S))
    parts = [m.group(0) for m in re.finditer(r'//[^\n]*', text)]
    parts += [m.group(0) for m in re.finditer(r'/\*.*?\*/', text, re.S)]
    return '\n'.join(parts)


def main():
    files = tracked()
    present = set(files)
    dirs = set()
    for f in files:
        d = os.path.dirname(f)
        while d:
            dirs.add(d)
            d = os.path.dirname(d)
    suffixes = set()
    for f in files:
        parts = f.split('/')
        for i in range(len(parts)):
            suffixes.add('/'.join(parts[i:]))
    stale = []
    for f in files:
        if not f.endswith(('.md', '.rs', '.js', '.py', '.sh', '.yaml', '.yml')):
            continue
        if f.startswith(('fuzz/corpus', 'web/vendor')):
            continue
        try:
            text = open(os.path.join(ROOT, f), encoding='utf-8').read()
        except (UnicodeDecodeError, FileNotFoundError):
            continue
        body = comments(f, text)
        cited = set()
        for m in DIR_WORD.finditer(body):
            p = m.group(1).rstrip('.')
            nxt = body[m.end():m.end() + 1]
            if nxt in ('*', '<', '$') or re.match(r'[\w.-]*\{', body[m.end():]) or p.endswith('/...'):
                continue
            cited.add(p)
            local = os.path.normpath(os.path.join(os.path.dirname(f), p))
            if (p not in present and p.rstrip('/') not in dirs and not ignored(p)
                    and local not in present and local not in dirs):
                stale.append((f, p))
        for m in WORD.finditer(body):
            p = m.group(1)
            if (p in cited or p in NOT_OURS or any(c.startswith(p) for c in cited)
                    or p.startswith('_') or re.match(r'^[A-Z][\w-]*\.js$', p)):
                continue
            if p.startswith('./') or p.startswith('../'):
                q = os.path.normpath(os.path.join(os.path.dirname(f), p))
                if q not in present and q not in dirs:
                    stale.append((f, p))
                continue
            if p.split('/')[0] in ('crates', 'docs', 'scripts', 'tests', 'src', 'web', 'api',
                                   'clients', 'benches', 'examples', 'fuzz', 'docker', '.ci'):
                continue
            if p not in suffixes:
                stale.append((f, p))
        if f.endswith('.md'):
            for m in MD_LINK.finditer(text):
                p = m.group(1)
                if re.match(r'^[a-z]+:', p) or p.startswith('/'):
                    continue
                q = os.path.normpath(os.path.join(os.path.dirname(f), p))
                if q not in present and q not in dirs:
                    stale.append((f, p))
    bad = 0
    for f, p in sorted(set(stale)):
        if (f, p) in KNOWN:
            print(f'{f}: cites `{p}`, which does not exist (known)')
        else:
            bad += 1
            print(f'{f}: cites `{p}`, which does not exist')
    for f, p in sorted(KNOWN - set(stale)):
        print(f'{f}: `{p}` is fixed: remove it from KNOWN')
    if bad:
        return 1
    print(f'every repository path cited in {len(files)} files exists')
    return 0


if __name__ == '__main__':
    sys.exit(main())
