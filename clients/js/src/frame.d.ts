export { FrameError } from './errors.js';

/** A version 3 frame's position encoding (version 2 frames read as `f32`). */
export type FrameEncoding = 'f32' | 'q16' | 'delta';

/** A decoded pose frame (api/ws-protocol.md, "Binary pose frames"). */
export interface Frame {
  /** Format version: 2 or 3. */
  version: 2 | 3;
  encoding: FrameEncoding;
  /** 0: the full mesh's solve; 1: a coarse preview. */
  level: 0 | 1;
  /** The solve had converged. */
  converged: boolean;
  /** The server stopped iterating until the next change. */
  settled: boolean;
  /** Session revision. */
  revision: number;
  /** The seq of the last drag included in this pose. */
  ackSeq: number;
  /** Iterations since the targets last changed. */
  iteration: number;
  vertexCount: number;
  /** The solver's objective (NaN when unknown). */
  objective: number;
  /** The pose's box `[min, max]` (version 3), else null. */
  bbox: [[number, number, number], [number, number, number]] | null;
  /** A delta key frame. */
  key: boolean;
  /** The frame's size in bytes. */
  bytes: number;
  /** x, y, z per vertex; null for a `delta` frame read by {@link parseFrame}. */
  positions: Float32Array | null;
}

/** A frame whose positions were decoded. */
export interface DecodedFrame extends Frame {
  positions: Float32Array;
}

export const FRAME_MAGIC: 'DEND';
export const FRAME_HEADER_BYTES: 40;
export const FRAME_V3_HEADER_BYTES: 96;
export const DELTA_STREAM_OFFSET: 148;
export const LEVEL_FULL: 0;
export const LEVEL_COARSE: 1;
export const FRAME_VERSIONS: readonly [2, 3];
export const ENCODINGS: readonly ['f32', 'q16', 'delta'];

/** The bytes of a frame: an ArrayBuffer or a view of one. */
export type FrameBytes = ArrayBuffer | ArrayBufferView;

/** Parses one frame; a `delta` frame's `positions` are null. Throws a FrameError. */
export function parseFrame(buf: FrameBytes): Frame;

/** Decodes one frame on its own (a `delta` one only if it is a key frame). */
export function decodeFrame(buf: FrameBytes): Promise<DecodedFrame>;

/** A connection's decoder: give it every frame of the connection, in order. */
export class FrameDecoder {
  constructor();
  /** The revision of the delta frame held, or null. */
  readonly base: number | null;
  /** Decodes the next frame; rejects with a FrameError. */
  decode(buf: FrameBytes): Promise<DecodedFrame>;
}
