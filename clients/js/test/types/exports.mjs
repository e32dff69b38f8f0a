// The declarations and the modules agree: every value a public entry point
// exports at run time is declared in its .d.ts, and every value its .d.ts
// declares exists at run time (TypeScript's checker reads the declarations).

import assert from 'node:assert/strict';
import { dirname, join, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';
import ts from 'typescript';

const pkg = resolve(dirname(fileURLToPath(import.meta.url)), '..', '..');
const entries = ['src/index', 'src/frame', 'src/three/index'];
const program = ts.createProgram(entries.map((e) => join(pkg, `${e}.d.ts`)), { noEmit: true, types: [] });
const checker = program.getTypeChecker();
for (const e of entries) {
  const file = program.getSourceFile(join(pkg, `${e}.d.ts`));
  const declared = checker.getExportsOfModule(checker.getSymbolAtLocation(file))
    .filter((s) => {
      const t = s.flags & ts.SymbolFlags.Alias ? checker.getAliasedSymbol(s) : s;
      return t.flags & ts.SymbolFlags.Value;
    })
    .map((s) => s.name)
    .sort();
  const runtime = Object.keys(await import(join(pkg, `${e}.js`))).sort();
  assert.deepEqual(declared, runtime, `${e}: the .d.ts declares the values the module exports`);
  console.log(`[types] ${e}: ${runtime.length} values, each declared`);
}
