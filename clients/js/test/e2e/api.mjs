// Every HTTP route of the client against the real `dend serve`, and the
// server's refusals as ApiErrors carrying its codes and statuses.

import assert from 'node:assert/strict';
import { mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { ApiError, Client, DendError } from '../../src/index.js';
import { freePort, log, run, startServer, stopServer, tube } from './lib.mjs';

/** Resolves with the ApiError `promise` rejects with. */
async function refusal(promise) {
  try {
    await promise;
  } catch (e) {
    assert.ok(e instanceof ApiError && e instanceof DendError, `an ApiError, not ${e}`);
    return e;
  }
  throw new Error('the request was not refused');
}

run('api', async () => {
  const dataDir = mkdtempSync(join(tmpdir(), 'dend-api-'));
  const { proc, base } = await startServer(dataDir, await freePort());
  try {
    const client = new Client(`${base}/`);
    assert.equal((await client.healthz()).status, 'ok');
    assert.equal((await client.ready()).status, 'ready');
    assert.match(await client.metrics(), /dend_/);
    const presets = await client.presets();
    assert.ok(presets.presets.some((p) => p.name === presets.default));

    const gen = await client.generate('creature');
    assert.ok(gen.vertices > 100 && gen.constraints, 'the creature comes with its constraints');
    const plane = await client.generate('plane', { nu: 6, nv: 6 });
    assert.equal((await client.mesh(plane.id)).vertices, plane.vertices);
    const obj = 'v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n';
    const file = await client.uploadFile(new Blob([obj]), 'obj');
    assert.equal(file.vertices, 4);
    assert.equal((await refusal(client.uploadFile('x', 'dwg'))).code, 'unsupported_format');
    const bad = await refusal(client.uploadMesh([[0, 0, 0]], [[0, 1, 2]]));
    assert.equal(bad.status, 422);
    assert.ok(['invalid_mesh', 'vertex_out_of_range'].includes(bad.code), bad.code);
    await client.deleteMesh(file.id);
    assert.equal((await refusal(client.mesh(file.id))).code, 'mesh_not_found');

    const { positions, triangles, constraints } = tube(11, 8);
    const mesh = await client.uploadMesh(positions.flat(), triangles.flat());
    assert.equal(mesh.vertices, positions.length);
    const s = await client.createSession(mesh.id, { max_iters: 200 });
    const info = await s.info();
    assert.equal(info.mesh_id, mesh.id);
    const accepted = await s.setConstraints(constraints, { ifRevision: info.constraints_revision });
    assert.equal((await refusal(s.setConstraints(constraints, { ifRevision: info.constraints_revision }))).code, 'stale_constraints');
    const ready = await s.waitReady();
    assert.equal(ready.constraints_revision, accepted.constraints_revision);
    assert.equal((await refusal(client.deleteMesh(mesh.id))).code, 'mesh_in_use');

    const moved = await s.drag('end', { translate: [0, 0.5, 0] });
    assert.ok(moved.settled);
    const last = constraints.handles[0].vertices.at(-1);
    assert.ok(Math.abs(moved.positions[last][1] - positions[last][1] - 0.5) < 1e-9);
    const twisted = await s.drag(0, { rotate: { axis: [1, 0, 0], degrees: 30 } });
    assert.ok(twisted.revision > moved.revision);
    assert.equal((await refusal(s.drag(5, { translate: [1, 0, 0] }))).code, 'unknown_handle');
    const f32 = await s.poseF32();
    const pose = await s.pose();
    assert.equal(f32.positions.length, 3 * positions.length);
    assert.ok(Math.abs(f32.positions[3 * last + 1] - pose.positions[last][1]) < 1e-6);
    const text = new TextDecoder().decode(await s.export('obj'));
    assert.equal(text.split('\n').filter((l) => l.startsWith('v ')).length, positions.length);
    const glb = new Uint8Array(await s.export('glb'));
    assert.equal(new TextDecoder().decode(glb.subarray(0, 4)), 'glTF');
    assert.equal((await refusal(s.export('glb', { as: 'morph-targets' }))).code, 'unsupported_export');
    const curv = await s.curvature();
    assert.equal(curv.mean.length, positions.length);

    const saved = await s.savePose('raised');
    assert.equal(saved.name, 'raised');
    assert.deepEqual((await s.poses()).map((p) => p.name), ['raised']);
    // a name in use is refused unless replacing is asked for
    assert.equal((await refusal(s.savePose('raised'))).code, 'pose_exists');
    assert.equal((await s.savePose('raised', { replace: true })).name, 'raised');
    assert.equal((await s.namedPose('raised')).positions.length, positions.length);
    assert.equal((await s.renamePose('raised', 'up')).name, 'up');
    assert.equal((await refusal(s.namedPose('raised'))).code, 'pose_not_found');
    await s.reset();
    const undone = await s.undo();
    assert.ok(Math.abs(undone.positions[last][1] - pose.positions[last][1]) < 1e-6, 'undo brings the twisted pose back');
    await s.redo();
    const restored = await s.restorePose('up');
    assert.ok(Math.abs(restored.positions[last][1] - pose.positions[last][1]) < 1e-6);
    await s.deletePose('up');
    assert.deepEqual(await s.poses(), []);

    const wrong = client.session(s.id, 'x'.repeat(64));
    const forbidden = await refusal(wrong.info());
    assert.deepEqual([forbidden.code, forbidden.status, forbidden.transient], ['forbidden', 403, false]);
    await s.delete();
    assert.equal((await refusal(s.info())).code, 'session_not_found');
    const down = await refusal(new Client('http://127.0.0.1:9').healthz());
    assert.deepEqual([down.code, down.status, down.transient], ['network', 0, true]);
    log('every route answered; refusals carry the server codes');
  } finally {
    await stopServer(proc);
    rmSync(dataDir, { recursive: true, force: true });
  }
});
