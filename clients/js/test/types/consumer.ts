// A consumer of every public type of dend-client, checked by
// `tsc --noEmit -p test/types` (the package imported by its name, through
// its `exports` map, as an application would).

import {
  Client, Session, SessionSocket, FrameDecoder, parseFrame, decodeFrame, deltaBody, errorOf, shouldReconnect,
  DendError, ApiError, FrameError, SessionError, ConnectionError,
  FRAME_ERROR_KINDS, FRAME_MAGIC, FRAME_HEADER_BYTES, FRAME_V3_HEADER_BYTES, DELTA_STREAM_OFFSET, LEVEL_FULL, LEVEL_COARSE,
  FRAME_VERSIONS, ENCODINGS, MESH_FORMATS, EXPORT_FORMATS, RECONNECT_CODES, RESEND_CODES, PROTOCOL_VERSION,
} from 'dend-client';
import type {
  Frame, DecodedFrame, FrameEncoding, FrameBytes, FrameErrorKind, MeshInfo, GeneratedMesh, GeneratedShape, GenerateParams,
  Params, Constraints, VertexSet, Handle, Rotation, Pose, PoseInfo, NamedPose, SessionInfo, SessionStateName, Curvature,
  Presets, Preset, ConstraintsAccepted, ClientOptions, WebSocketConstructor, Triples, RequestOptions, ExportOptions,
  StreamOptions, MeshFormat, ExportFormat, AssetSummary, AssetGroup, Warning, Vec3, HandleRef,
  DragDelta, SocketOptions, SocketEvents, SocketStats, StateEvent, ServerEvent, CloseInfo,
} from 'dend-client';
import { SessionGeometry, HandleDragControls, geometryFromMesh, handleIndexOf } from 'dend-client/three';
import type { SessionGeometryEvents, HandleDragEvents } from 'dend-client/three';
import { decodeFrame as decodeAlone } from 'dend-client/frame';
import { Mesh, MeshStandardMaterial, PerspectiveCamera } from 'three';

const opts: ClientOptions = { fetch: globalThis.fetch, WebSocket: globalThis.WebSocket as WebSocketConstructor };
const client = new Client('http://127.0.0.1:8080', opts);

async function everyRoute(): Promise<void> {
  const h: { status: string; instance: string | null } = await client.healthz();
  const r: { status: string } = await client.ready();
  const m: string = await client.metrics();
  const p: Presets = await client.presets();
  const first: Preset | undefined = p.presets[0];
  const tri: Triples = [[0, 1, 2]];
  const mesh: MeshInfo = await client.uploadMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], tri);
  const fmt: MeshFormat = 'obj';
  const file: MeshInfo = await client.uploadFile('v 0 0 0', fmt);
  const asset: AssetSummary | undefined = file.asset;
  const group: AssetGroup | undefined = asset?.groups?.[0];
  const shape: GeneratedShape = 'creature';
  const gp: GenerateParams = { nu: 8 };
  const gen: GeneratedMesh = await client.generate(shape, gp);
  const again: MeshInfo = await client.mesh(gen.id);
  await client.deleteMesh(again.id);
  const params: Params = { preset: 'elastica', max_iters: 50 };
  const session: Session = await client.createSession(mesh.id, params);
  const same: Session = client.session(session.id, session.token);
  const rot: Rotation = { axis: [0, 0, 1], degrees: 10 };
  const handle: Handle = { name: 'h', vertices: { sphere: { center: [0, 0, 0], radius: 1 } }, rotate: rot };
  const fixed: VertexSet = [0];
  const c: Constraints = { fixed, handles: [handle] };
  const accepted: ConstraintsAccepted = await same.setConstraints(c, { ifRevision: 0 });
  const state: SessionStateName = accepted.state;
  const info: SessionInfo = await same.waitReady({ timeoutMs: 1000 });
  const w: Warning | undefined = info.warnings[0];
  const delta: DragDelta = { translate: [0, 0.1, 0], quaternion: [0, 0, 0, 1] };
  const ref: HandleRef = 'h';
  const pose: Pose = await same.drag(ref, delta, { maxIters: 10 });
  const v: Vec3 = pose.positions[0];
  const f32: { revision: number; positions: Float32Array } = await same.poseF32();
  const ef: ExportFormat = 'glb';
  const eo: ExportOptions = { as: 'morph-targets', animation: true };
  const bytes: ArrayBuffer = await same.export(ef, eo);
  const curv: Curvature = await same.curvature();
  await same.undo(); await same.redo(); await same.reset();
  const saved: PoseInfo = await same.savePose('a', { replace: true });
  const list: PoseInfo[] = await same.poses();
  const named: NamedPose = await same.namedPose('a');
  await same.renamePose('a', 'b'); await same.restorePose('b'); await same.deletePose('b');
  const so: StreamOptions = { window: 1, encoding: 'q16', maxFps: 60, refineFps: 30 };
  const url: string = same.socketUrl(so);
  const ro: RequestOptions = { json: {}, token: same.token };
  const res: Response = await client.request('GET', '/healthz', ro);
  const err: ApiError = await errorOf(res);
  const body: Record<string, unknown> = deltaBody(delta);
  const sopts: SocketOptions = { window: 1, encoding: 'delta', ack: 'manual', reconnectTimeoutMs: 1000 };
  const socket: SessionSocket = await same.connect(sopts);
  socket.on('frame', (fr: DecodedFrame) => { socket.ack(fr); });
  socket.on('state', (s: StateEvent) => s.constraints_revision);
  socket.on('event', (e: ServerEvent) => (e.type === 'error' ? e.code : e.type));
  socket.on('error', (e: SessionError | FrameError) => e.code);
  socket.on('close', (ci: CloseInfo) => ci.error?.code);
  socket.on('reconnected', (x: { ackSeq: number; resent: number; sent: number }) => x.ackSeq + x.sent);
  const seq: number = socket.drag(0, delta);
  const st: SocketStats = socket.stats();
  const ev: keyof SocketEvents = 'reconnecting';
  const settled: DecodedFrame = await socket.settledFrame(1000);
  const pos: Float32Array | null = socket.positions;
  const level: 0 | 1 = socket.level;
  socket.grab(0); socket.release(0); socket.undo(); socket.redo(); socket.savePose('x', { replace: false }); socket.restorePose('x');
  socket.setConstraints(c, 3); socket.ping(1); socket.send({ type: 'ping' });
  const next: DecodedFrame = await socket.nextFrame((x) => x.level === LEVEL_COARSE, 100);
  socket.close();
  void [h, r, m, first, group, w, state, v, f32, bytes, curv, saved, list, named, url, err, body, seq, st, ev, settled, pos, level, next];
}

async function frames(buf: ArrayBuffer): Promise<void> {
  const bytes: FrameBytes = new Uint8Array(buf);
  const f: Frame = parseFrame(bytes);
  const enc: FrameEncoding = f.encoding;
  const dec = new FrameDecoder();
  const d: DecodedFrame = await dec.decode(buf);
  const alone: DecodedFrame = await decodeFrame(buf);
  const alone2: DecodedFrame = await decodeAlone(buf);
  const base: number | null = dec.base;
  try {
    parseFrame(new ArrayBuffer(3));
  } catch (e) {
    if (e instanceof FrameError) {
      const k: FrameErrorKind = e.kind;
      const got: number | undefined = e.got;
      void [k, got];
    } else if (e instanceof ApiError) {
      const t: boolean = e.transient;
      void t;
    } else if (e instanceof SessionError || e instanceof ConnectionError) {
      const c: string = e.code;
      void c;
    } else if (e instanceof DendError) {
      void e.code;
    }
  }
  const consts: number[] = [FRAME_HEADER_BYTES, FRAME_V3_HEADER_BYTES, DELTA_STREAM_OFFSET, LEVEL_FULL, LEVEL_COARSE, PROTOCOL_VERSION, ...FRAME_VERSIONS, ...RECONNECT_CODES];
  const names: string[] = [FRAME_MAGIC, ...ENCODINGS, ...MESH_FORMATS, ...EXPORT_FORMATS, ...RESEND_CODES, ...FRAME_ERROR_KINDS];
  const again: boolean = shouldReconnect(4012);
  void [enc, d, alone, alone2, base, consts, names, again];
}

function three(socket: SessionSocket, canvas: HTMLCanvasElement): void {
  const geometry = geometryFromMesh([0, 0, 0, 1, 0, 0, 0, 1, 0], [0, 1, 2]);
  const follow = new SessionGeometry(socket, geometry, { normals: true });
  follow.addEventListener('dendframe', (e: SessionGeometryEvents['dendframe']) => { const c: boolean = e.coarse; void c; });
  const coarse: boolean = follow.coarse;
  const object = new Mesh(geometry, new MeshStandardMaterial());
  const camera = new PerspectiveCamera();
  const handleOf: Int32Array = handleIndexOf(3, [{ vertices: [2] }]);
  const drag = new HandleDragControls(socket, object, camera, canvas, { handleOf });
  drag.addEventListener('drag', (e: HandleDragEvents['drag']) => { const s: number = e.seq; void s; });
  drag.enabled = false;
  drag.dispose();
  follow.dispose();
  void coarse;
}

void [everyRoute, frames, three];
