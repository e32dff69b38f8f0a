// Where the frame fixtures written by the Rust encoder's test
// (crates/protocol/tests/js_fixtures.rs) are: $DEND_JS_FIXTURES, else a
// fresh folder the test is run into (`cargo test`, a few seconds once built).

import { execFileSync } from 'node:child_process';
import { existsSync, mkdtempSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { dirname, join, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';

export const repo = resolve(dirname(fileURLToPath(import.meta.url)), '..', '..', '..');

export function fixtureDir() {
  const given = process.env.DEND_JS_FIXTURES;
  if (given && existsSync(join(given, 'manifest.json'))) return given;
  const dir = given || mkdtempSync(join(tmpdir(), 'dend-js-fixtures-'));
  execFileSync('cargo', ['test', '-q', '-p', 'dend-protocol', '--test', 'js_fixtures'], {
    cwd: repo, stdio: ['ignore', 'ignore', 'inherit'], env: { ...process.env, DEND_JS_FIXTURES: dir },
  });
  return dir;
}
