import type { DecodedFrame } from './frame.js';
import type { Session, HandleRef, Vec3, Constraints, SessionStateName, Warning, PoseInfo, WebSocketConstructor } from './api.js';
import type { DendError, FrameError, SessionError } from './errors.js';

export const RECONNECT_CODES: readonly number[];
export const RESEND_CODES: readonly string[];
export function shouldReconnect(code: number): boolean;

/** A drag's delta: rotate about the handle's pivot, then translate. */
export interface DragDelta {
  translate?: Vec3 | ArrayLike<number>;
  rotate?: { axis: Vec3 | ArrayLike<number>; degrees: number };
  quaternion?: [number, number, number, number] | ArrayLike<number>;
}

export interface SocketOptions {
  /** Frames in flight (1). */
  window?: number;
  /** Frame encoding ('delta'). */
  encoding?: 'f32' | 'q16' | 'delta';
  maxFps?: number;
  /** Refinement frames per second at most (30). */
  refineFps?: number;
  /** When frames are acknowledged. */
  ack?: 'animation' | 'frame' | 'manual';
  reconnect?: boolean;
  reconnectTimeoutMs?: number;
  resyncTimeoutMs?: number;
  openTimeoutMs?: number;
  WebSocket?: WebSocketConstructor;
}

/** The socket's `state` event. */
export interface StateEvent {
  type: 'state'; you?: number; id: string; mesh_id: string; state: SessionStateName; revision: number;
  handles: string[]; peers: number; can_undo: boolean; can_redo: boolean; vertices: number;
  constraints: Constraints | null; constraints_revision: number; warnings: Warning[];
  build_stage: 'assembly' | 'symbolic' | 'numeric' | null; poses: PoseInfo[];
}
/** Any JSON message of the server. */
export type ServerEvent =
  | StateEvent
  | { type: 'build_progress'; stage: 'assembly' | 'symbolic' | 'numeric' }
  | { type: 'ready'; revision: number }
  | { type: 'error'; code: string; message: string; seq?: number | null }
  | { type: 'handle_grabbed' | 'handle_released'; handle: number; client: number }
  | { type: 'peer_joined' | 'peer_left'; client: number }
  | { type: 'pong'; nonce: unknown };

export interface CloseInfo { code: number; reason: string; error: DendError | null }

export interface SocketEvents {
  frame: DecodedFrame;
  event: ServerEvent;
  state: StateEvent;
  error: SessionError | FrameError;
  open: undefined;
  reconnecting: { code: number; reason: string };
  /** `resent`: drags sent before and sent again; `sent`: every drag sent at the resumption. */
  reconnected: { ackSeq: number; resent: number; sent: number };
  close: CloseInfo;
}

/** The stream's figures. */
export interface SocketStats {
  fps: number;
  latencyMs: number | null;
  latencyP50Ms: number | null;
  latencyP95Ms: number | null;
  settleMs: number | null;
  frames: number;
  bytes: number;
  levels: [number, number];
  encodings: { f32: number; q16: number; delta: number };
  unacked: number;
  maxUnacked: number;
  pendingDrags: number;
  reconnects: number;
  resentDrags: number;
  decodeErrors: number;
}

/** A session's live WebSocket. */
export class SessionSocket {
  constructor(session: Session, options?: SocketOptions);
  readonly session: Session;
  readonly status: 'connecting' | 'open' | 'reconnecting' | 'closed';
  /** The last frame, or null. */
  readonly latest: DecodedFrame | null;
  /** The last `state` event, or null. */
  readonly state: StateEvent | null;
  /** This connection's client id. */
  readonly clientId: number | null;
  readonly positions: Float32Array | null;
  readonly level: 0 | 1;
  readonly settled: boolean;
  readonly converged: boolean;
  on<K extends keyof SocketEvents>(type: K, fn: (value: SocketEvents[K]) => void): () => void;
  stats(): SocketStats;
  open(): Promise<this>;
  /** Sends a drag; returns its seq. Kept until acknowledged, sent again after a reconnection. */
  drag(handle: HandleRef, delta: DragDelta): number;
  ack(frame?: DecodedFrame): void;
  send(message: Record<string, unknown>): boolean;
  grab(handle: HandleRef): boolean;
  release(handle: HandleRef): boolean;
  setConstraints(constraints: Constraints, ifRevision?: number | null): boolean;
  undo(): boolean;
  redo(): boolean;
  savePose(name: string, options?: { replace?: boolean }): boolean;
  restorePose(name: string): boolean;
  ping(nonce?: unknown): boolean;
  nextFrame(pred?: (frame: DecodedFrame) => boolean, timeoutMs?: number): Promise<DecodedFrame>;
  settledFrame(timeoutMs?: number): Promise<DecodedFrame>;
  close(): void;
}
