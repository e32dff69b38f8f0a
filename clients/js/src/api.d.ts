import type { SessionSocket, SocketOptions, DragDelta } from './session.js';

export type Vec3 = [number, number, number];
export type HandleRef = number | string;

export const MESH_FORMATS: readonly ['json', 'obj', 'off', 'ply', 'stl', 'gltf', 'glb'];
export const EXPORT_FORMATS: readonly ['obj', 'off', 'ply', 'stl', 'gltf', 'glb'];
export type MeshFormat = (typeof MESH_FORMATS)[number];
export type ExportFormat = (typeof EXPORT_FORMATS)[number];

export interface AssetGroup { kind: 'g' | 'o' | 'node' | 'mesh' | 'primitive'; name?: string; index?: number; primitive?: number; triangles: number; vertices: number }
export interface AssetSummary { format: 'glb' | 'gltf' | 'obj' | 'ply'; name?: string; asset_vertices: number; attributes: string[]; groups?: AssetGroup[] }
/** A stored mesh. */
export interface MeshInfo { id: string; vertices: number; triangles: number; bbox: [Vec3, Vec3]; asset?: AssetSummary }
/** A generated mesh (the creature comes with its default constraints). */
export interface GeneratedMesh extends MeshInfo { constraints?: Constraints }
export type GeneratedShape = 'bar' | 'cylinder' | 'flag' | 'plane' | 'bumpy-plane' | 'torus' | 'creature';
export interface GenerateParams { nu?: number; nv?: number; size?: number; size2?: number; amplitude?: number }

/** Solver parameters (api/openapi.yaml, `Params`); every field optional. */
export interface Params {
  preset?: 'characters' | 'elastica';
  energy?: string | { combined: { ks: number; kb: number } };
  lambda1?: number; lambda2?: number;
  detail?: 'linear' | 'nonlinear';
  mode?: 'default' | 'paper';
  tol?: number; max_iters?: number; anderson?: number;
  formulation?: 'elastic' | 'least_squares' | 'square' | 'square_lu';
  stretch?: number; bending?: number; area?: number; laplacian?: number;
  coarse_ratio?: number;
  corrections?: 'while-faster' | 'while-gaining';
  correction_period?: number;
  [extra: string]: unknown;
}

/** A vertex set: indices, a box, a ball or a named part of the asset. */
export type VertexSet =
  | number[]
  | { box: { min: Vec3; max: Vec3 } }
  | { sphere: { center: Vec3; radius: number } }
  | { group: string | { node: HandleRef } | { mesh: HandleRef } | { primitive: [HandleRef, number] } };
export type Rotation = { axis: Vec3; degrees: number } | { quaternion: [number, number, number, number] };
export interface Handle { name?: string; vertices: VertexSet; translate?: Vec3; rotate?: Rotation; pivot?: Vec3; positions?: Vec3[] }
/** A constraint set (api/constraints.schema.json). */
export interface Constraints { fixed?: VertexSet; fixed_positions?: Vec3[]; handles?: Handle[] }

export interface PoseInfo { name: string; index: number; revision: number; created_unix: number }
export interface NamedPose extends PoseInfo { positions: Vec3[] }
/** A pose as JSON (f64 positions). */
export interface Pose { revision: number; ack_seq: number; iteration: number; converged: boolean; settled: boolean; objective: number | null; positions: Vec3[] }
export interface Warning { code: string; message: string; [extra: string]: unknown }
export type SessionStateName = 'empty' | 'building' | 'ready' | 'failed';
/** `GET /v1/sessions/{id}`. */
export interface SessionInfo {
  id: string; mesh_id: string; state: SessionStateName; revision: number; handles: string[]; peers: number;
  can_undo: boolean; can_redo: boolean; vertices: number; constraints: Constraints | null; constraints_revision: number;
  build_stage: 'assembly' | 'symbolic' | 'numeric' | null; poses: PoseInfo[]; warnings: Warning[];
}
export interface Curvature { revision: number; mean: number[]; gaussian: number[]; g: number[] }
export interface Preset { name: string; label: string; description: string; params: Params }
export interface Presets { default: string; presets: Preset[] }
export interface ConstraintsAccepted { state: SessionStateName; constraints_revision: number }
export interface ClientOptions { fetch?: typeof fetch; WebSocket?: WebSocketConstructor }
/** A WebSocket constructor (the browser's, Node's, or the `ws` package's). */
export type WebSocketConstructor = new (url: string) => WebSocket;
export type Triples = ArrayLike<number> | ArrayLike<ArrayLike<number>>;
export interface RequestOptions { body?: BodyInit | null; json?: unknown; token?: string; headers?: Record<string, string>; signal?: AbortSignal }

/** The error of a refused answer. */
export function errorOf(res: Response): Promise<import('./errors.js').ApiError>;
/** The drag fields of a delta. */
export function deltaBody(delta?: DragDelta): Record<string, unknown>;

/** A client of one dend server. */
export class Client {
  constructor(base?: string, options?: ClientOptions);
  readonly base: string;
  request(method: string, path: string, options?: RequestOptions): Promise<Response>;
  json<T = unknown>(method: string, path: string, body?: unknown, token?: string, headers?: Record<string, string>): Promise<T>;
  healthz(): Promise<{ status: string; instance: string | null }>;
  ready(): Promise<{ status: string }>;
  metrics(): Promise<string>;
  presets(): Promise<Presets>;
  uploadMesh(positions: Triples, triangles: Triples): Promise<MeshInfo>;
  uploadFile(data: Blob | ArrayBuffer | ArrayBufferView | string, format?: MeshFormat): Promise<MeshInfo>;
  generate(shape: GeneratedShape, params?: GenerateParams): Promise<GeneratedMesh>;
  mesh(id: string): Promise<MeshInfo>;
  deleteMesh(id: string): Promise<null>;
  createSession(meshId: string, params?: Params): Promise<Session>;
  session(id: string, token: string): Session;
}

export interface ExportOptions { as?: 'pose' | 'morph-targets'; animation?: boolean }
export interface StreamOptions { window?: number | null; encoding?: 'f32' | 'q16' | 'delta' | null; maxFps?: number; refineFps?: number }

/** A session and its token: every session route. */
export class Session {
  constructor(client: Client, id: string, token: string);
  readonly client: Client;
  readonly id: string;
  readonly token: string;
  info(): Promise<SessionInfo>;
  delete(): Promise<null>;
  setConstraints(constraints: Constraints, options?: { ifRevision?: number | null }): Promise<ConstraintsAccepted>;
  waitReady(options?: { timeoutMs?: number }): Promise<SessionInfo>;
  drag(handle: HandleRef, delta: DragDelta, options?: { maxIters?: number }): Promise<Pose>;
  pose(): Promise<Pose>;
  poseF32(): Promise<{ revision: number; positions: Float32Array }>;
  export(format?: ExportFormat, options?: ExportOptions): Promise<ArrayBuffer>;
  curvature(): Promise<Curvature>;
  undo(): Promise<Pose>;
  redo(): Promise<Pose>;
  reset(): Promise<Pose>;
  poses(): Promise<PoseInfo[]>;
  savePose(name: string, options?: { replace?: boolean }): Promise<PoseInfo>;
  namedPose(name: string): Promise<NamedPose>;
  renamePose(name: string, to: string): Promise<PoseInfo>;
  deletePose(name: string): Promise<null>;
  restorePose(name: string): Promise<Pose>;
  socketUrl(options?: StreamOptions): string;
  connect(options?: SocketOptions): Promise<SessionSocket>;
}
